"""The thesis's Python API (Figure 4.2) on the same code as layout files::

    from trackgen import TrackGenerator
    from pieces import TURN_LEFT, CROSSROADS
    gen = TrackGenerator()
    gen.add_piece(CROSSROADS)
    gen.add_piece(TURN_LEFT, angle_deg=90, radius_m=0.6)
    track = gen.build()        # a trackgen.Track (chained, not yet validated)

Errors point at the ``add_piece`` call in the caller's script (``script.py:12: ...``).
"""
from __future__ import annotations

import math
import sys

from pieces.spec import PARAMS, PieceType, TrackSettings

from .chain import Track, chain
from .errors import LayoutError
from .layout import MAX_PIECES, Layout, LayoutEntry, range_text, sanitize_name


def _caller(depth: int = 2) -> tuple[str, int]:
    """File and line of the user's call ``depth`` frames up."""
    frame = sys._getframe(depth)
    return frame.f_code.co_filename, frame.f_lineno


class TrackGenerator:
    """Collects pieces in driving order; :meth:`build` chains them into a :class:`Track`.

    ``settings``: :class:`pieces.TrackSettings` (default widths); ``name``: track name. A
    wrong ``settings`` or ``name`` raises :class:`LayoutError` naming the calling line, as
    a wrong ``add_piece`` argument does.
    """

    def __init__(self, settings: TrackSettings | None = None, *, name: str = "track") -> None:
        if settings is not None and not isinstance(settings, TrackSettings):
            path, line = _caller()
            raise LayoutError(path, line, f"TrackGenerator(settings={settings!r}): expected a "
                                          "pieces.TrackSettings")
        if not isinstance(name, str):
            path, line = _caller()
            raise LayoutError(path, line, f"TrackGenerator(name={name!r}): expected a string")
        self.settings = settings or TrackSettings()
        self.name = sanitize_name(name)
        self._entries: list[LayoutEntry] = []
        self._path = "<python>"

    def add_piece(self, kind: PieceType | str, **params: float) -> "TrackGenerator":
        """Append a piece. ``kind``: a :class:`pieces.PieceType` (or its name). ``params``:
        internal-unit keywords (``length_m``, ``radius_m``, ``angle_rad``, ``offset_m``,
        ``mark_length_m``) or ``angle_deg`` in degrees. Raises :class:`LayoutError` naming
        the calling line. Returns ``self``."""
        path, line = _caller()
        self._path = path
        if isinstance(kind, str) and kind.upper() in PieceType.__members__:
            kind = PieceType[kind.upper()]
        if not isinstance(kind, PieceType):
            raise LayoutError(path, line, f"add_piece({kind!r}): expected a pieces.PieceType "
                                          f"(one of {', '.join(PieceType.__members__)})")
        if len(self._entries) >= MAX_PIECES:
            raise LayoutError(path, line, f"too many pieces (> {MAX_PIECES})")
        specs = PARAMS[kind]
        by_kwarg = {s.internal: s for s in specs.values()}
        by_kwarg.update({f"{s.name}_deg": s for s in specs.values() if s.unit == "deg"})
        typed: dict[str, float] = {}
        for key, value in params.items():
            spec = by_kwarg.get(key)
            if spec is None:
                raise LayoutError(path, line, f"{kind.name}: unknown parameter {key!r} (expected "
                                              f"one of {', '.join(sorted(by_kwarg))})")
            if spec.name in typed:
                raise LayoutError(path, line, f"{kind.name}: {spec.name} given twice")
            try:
                number = float(value)
            except (TypeError, ValueError):
                raise LayoutError(path, line, f"{kind.name} {key}={value!r}: expected a number") from None
            if spec.unit == "deg" and key.endswith("_rad"):
                number = math.degrees(number)
            if not spec.contains(number):
                raise LayoutError(path, line, f"{kind.name} {key}={value!r}: expected {range_text(spec)}")
            typed[spec.name] = number
        self._entries.append(LayoutEntry(kind, typed, line))
        return self

    def layout(self, _depth: int = 2) -> Layout:
        """The pieces so far as a :class:`Layout` (path = the calling script)."""
        if not self._entries:
            path, line = _caller(_depth)
            raise LayoutError(path, line, "empty track: add pieces with add_piece() first")
        return Layout(path=self._path, name=self.name, entries=tuple(self._entries),
                      settings=self.settings)

    def build(self) -> Track:
        """Chain the pieces (see :func:`trackgen.chain`)."""
        return chain(self.layout(_depth=3))

    def __len__(self) -> int:
        return len(self._entries)

