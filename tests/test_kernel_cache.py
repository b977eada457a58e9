"""The line kernel's on-disk numba cache is verified (issue 13 item 16, the cache part): a
truncated or changed entry is dropped and rebuilt, never served; track loading keeps no
cache at all."""
from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import pytest

from simrunner.sensors import kernel_cache

ROOT = Path(__file__).resolve().parents[1]


def _fake_dispatcher(folder: Path) -> SimpleNamespace:
    index = folder / "k.f-1.py311.nbi"
    return SimpleNamespace(_cache=SimpleNamespace(_cache_file=SimpleNamespace(_index_path=str(index))))


def _entry(folder: Path) -> tuple[Path, Path]:
    index, data = folder / "k.f-1.py311.nbi", folder / "k.f-1.py311.1.nbc"
    index.write_bytes(b"index")
    data.write_bytes(b"machine code" * 100)
    return index, data


@pytest.mark.parametrize("damage", ["truncate", "flip", "extra", "remove_data", "no_manifest",
                                    "bad_manifest"])
def test_damaged_entry_is_dropped(tmp_path, damage):
    d = _fake_dispatcher(tmp_path)
    assert kernel_cache.verify(d) == "empty"
    index, data = _entry(tmp_path)
    if damage != "no_manifest":
        kernel_cache.record(d)
        assert kernel_cache.verify(d) == "verified"
    if damage == "truncate":
        data.write_bytes(data.read_bytes()[:50])
    elif damage == "flip":
        data.write_bytes(b"Machine code" + data.read_bytes()[12:])
    elif damage == "extra":
        (tmp_path / "k.f-1.py311.2.nbc").write_bytes(b"x")
    elif damage == "remove_data":
        data.unlink()
    elif damage == "bad_manifest":
        (tmp_path / ("k.f-1.py311.nbi" + kernel_cache.MANIFEST_SUFFIX)).write_text("{not json")
    assert kernel_cache.verify(d) == "dropped"
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # the entry and its manifest are gone


def test_unrelated_files_are_left_alone(tmp_path):
    d = _fake_dispatcher(tmp_path)
    _entry(tmp_path)
    (tmp_path / "other.g-3.py311.1.nbc").write_bytes(b"other")
    assert kernel_cache.verify(d) == "dropped"
    assert [p.name for p in tmp_path.iterdir()] == ["other.g-3.py311.1.nbc"]


def test_record_writes_sums_once(tmp_path):
    d = _fake_dispatcher(tmp_path)
    index, data = _entry(tmp_path)
    kernel_cache.record(d)
    manifest = tmp_path / (index.name + kernel_cache.MANIFEST_SUFFIX)
    sums = json.loads(manifest.read_text())
    assert set(sums) == {index.name, data.name} and all(len(v) == 64 for v in sums.values())
    mtime = manifest.stat().st_mtime_ns
    kernel_cache.record(d)
    assert manifest.stat().st_mtime_ns == mtime


# No end-to-end drive here: runs use the NumPy line row (simrunner/sensors/line_row.py), so
# numba's cache entry can no longer break a drive; the checks above cover the reference kernel.


def test_track_loading_keeps_no_cache():
    text = "\n".join(p.read_text() for p in (ROOT / "simrunner" / "track").glob("*.py"))
    text += "\n".join(p.read_text() for p in (ROOT / "worlds").glob("*.py"))
    for word in ("~/.cache", "XDG_CACHE", "TRACK_CACHE", "expanduser"):
        assert word not in text
