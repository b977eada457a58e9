"""What a run leaves to read: the run's plot (:mod:`~simrunner.reports.plot`), the debug video
(:mod:`~simrunner.reports.video`, one frame's layout in :mod:`~simrunner.reports.video_frame`)
and the output files of a run (:mod:`~simrunner.reports.outputs`: CSV, video, plot, summary).

Built from a run's log and track; below :mod:`simrunner.run`, which calls it.
"""
