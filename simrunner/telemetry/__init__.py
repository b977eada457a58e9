"""The run log: its schema and units (docs/telemetry.md), reading and writing it
(:mod:`~simrunner.telemetry.log`), writing it as the run goes (:mod:`~simrunner.telemetry.stream`),
logs with other columns or units (:mod:`~simrunner.telemetry.columns`; a controller's norm
functions come in as plain functions, from :mod:`simrunner.run.norms`) and merged logs whose
streams have their own rates (:mod:`~simrunner.telemetry.sparse`).

Nothing here runs a simulation or a controller: the room sits below :mod:`simrunner.run`.
"""
