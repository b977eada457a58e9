"""Layout-file track generator: layout text -> pieces -> chained Track -> checks -> files.

Public API::

    load_layout(path) -> Layout            parse_layout(text, path=...) -> Layout
    chain(layout) -> Track                 TrackGenerator().add_piece(...).build() -> Track
    validate_track(track, min_turn_radius_m) -> list[Problem]
    check_layout(layout, car=None) -> Checked(track, geometry, problems)
    validate_path(path, car=None) -> list[Problem]      (layout file or build folder)
    trackgen.build.build(layout, out_dir, *, force=False, car=None) -> BuildResult

Errors: :class:`TrackError` (root), :class:`LayoutError` (``path:line: message``),
:class:`ValidationFailed` (``.problems``), :class:`OutputError` (cannot write).
"""
from .errors import LayoutError, TrackError
from .layout import Layout, LayoutEntry, load_layout, parse_layout
from .chain import PlacedPiece, ReEntry, Track, chain
from .generator import TrackGenerator
from .validate import Problem, validate_track
from .build import BuildResult, OutputError, ValidationFailed, check_layout, validate_path

__all__ = [
    "TrackError", "LayoutError", "Layout", "LayoutEntry", "load_layout", "parse_layout",
    "PlacedPiece", "ReEntry", "Track", "chain", "TrackGenerator", "Problem", "validate_track",
    "BuildResult", "OutputError", "ValidationFailed", "check_layout", "validate_path",
]
