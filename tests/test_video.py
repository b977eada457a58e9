"""Debug video: frame layout, frame count and size, written off the control path."""
from __future__ import annotations

import shutil
import textwrap
from pathlib import Path

import cv2
import numpy as np
import pytest

from pieces.pose import Pose2
from simrunner.errors import SimError
from simrunner.run.runner import drive
from simrunner.reports.video import FRAME_H, FRAME_W, Composer, FrameRecord, Layout, TrackView, VideoRecorder, compose
from simrunner.track import load_track

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _frames(path):
    cap = cv2.VideoCapture(str(path))
    assert cap.isOpened()
    n, shapes = 0, set()
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        n += 1
        shapes.add(frame.shape)
    cap.release()
    return n, shapes


def test_drive_writes_every_second_frame_of_the_50_fps_camera(tmp_path):
    ctrl = tmp_path / "c.py"
    ctrl.write_text(textwrap.dedent("""\
        def main(s):
            s.set_speed_and_servo(0.8, 0.0)
            for i in range(30):
                row = s.get_image(s.line_row)
                s.add_data([f"frame {i}"])
                s.add_data(255 - row)
        """))
    r = drive(ctrl, video=tmp_path / "v.mp4", csv=tmp_path / "t.csv")
    assert r.outcome == "controller_returned"
    n, shapes = _frames(tmp_path / "v.mp4")
    assert len(r.log) == 31 and n == 16  # frames 0, 2, .., 30 of the camera's 50 fps
    assert shapes == {(FRAME_H, FRAME_W, 3)}
    assert not (tmp_path / "v.partial.mp4").exists()
    cap = cv2.VideoCapture(str(tmp_path / "v.mp4"))
    assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(25.0)


def test_video_fps_keeps_every_camera_frame(tmp_path):
    """--video-fps 50 (drive(video_fps=50)): every frame of the 50 fps camera, at 50 fps."""
    from click.testing import CliRunner

    from simrunner.cli import main as cli

    ctrl = tmp_path / "c.py"
    ctrl.write_text("def main(s):\n    s.set_speed_and_servo(0.8, 0.0)\n    for i in range(30):\n"
                    "        s.get_image(s.line_row)\n")
    res = CliRunner().invoke(cli, ["drive", str(ctrl), "--video", str(tmp_path / "v.mp4"), "--video-fps", "50"])
    assert res.exit_code == 0, res.output
    n, _ = _frames(tmp_path / "v.mp4")
    assert n == 31
    cap = cv2.VideoCapture(str(tmp_path / "v.mp4"))
    assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(50.0)


def test_video_is_closed_and_kept_when_the_controller_crashes(tmp_path):
    ctrl = tmp_path / "c.py"
    ctrl.write_text("def main(s):\n    for _ in range(10):\n        s.get_image()\n    raise RuntimeError('boom')\n")
    r = drive(ctrl, video=tmp_path / "v.mp4")
    assert r.outcome == "controller_error"
    n, _ = _frames(tmp_path / "v.mp4")
    assert n == 6  # frames 0, 2, .., 10


def _record(**kw):
    img = np.full((128, 128), 200, np.uint8)
    img[:, :10] = 0
    rec = dict(frame=3, t_s=0.06, pose=Pose2(0, 0, 0),
               state=dict(speed=1.0, steer=0.1, speed_cmd=1.2, steer_cmd=0.1, lap=0, off_track=False),
               image=img, line=img[60:61], line_row=60, text=("hello",), lines=None)
    rec.update(kw)
    return FrameRecord(**rec)


def test_compose_layout_has_camera_line_and_track_panels():
    rec = _record(lines=np.zeros((2, 128), np.uint8))
    layout = Layout.for_frame((128, 128), None)
    out = compose(rec, None, laps=1)
    assert out.shape == (FRAME_H, FRAME_W, 3) and out.dtype == np.uint8
    assert out[100, 300].tolist() == [200, 200, 200]  # camera image x3 at x 0..384
    assert out[100, 20].tolist() == [0, 0, 0]  # its dark left columns (0..9 -> 0..29)
    x0 = layout.middle[0] + 8
    assert out[40, x0 + 200].tolist() == [200, 200, 200]  # the line, stretched
    assert out[40, x0 + 5].tolist() == [0, 0, 0]  # its dark left part


def test_camera_image_is_drawn_three_times_its_size():
    img = np.full((128, 128), 255, np.uint8)
    out = compose(_record(image=img, line=img[60:61], text=()), None, laps=1)
    white = np.all(out == 255, axis=2)
    rows, cols = np.flatnonzero(white.any(axis=1)), np.flatnonzero(white[:, :400].any(axis=0))
    assert rows[0] == 0 and cols[0] == 0
    # the white block of the camera image (the row markers are red): 384 x 384
    assert np.count_nonzero(white[:, :390].any(axis=0)) == 384
    assert np.count_nonzero(white[:390, :384].all(axis=1)) >= 380


def test_controller_text_sits_under_its_processed_lines():
    """Thesis Fig. 3.7: camera line, under it the controller's line, under that its text."""
    lines = np.full((1, 128), 90, np.uint8)
    rec = _record(lines=lines, text=("first text line", "second"))
    layout = Layout.for_frame((128, 128), 0.7)
    out = compose(rec, None, laps=1, layout=layout)
    x0, _, x1, _ = layout.middle
    middle = out[:, x0:x1]
    line_rows = np.flatnonzero(np.all(middle == 90, axis=2).sum(axis=1) > 100)
    text_rows = np.flatnonzero((middle.min(axis=2) > 200).sum(axis=1) > 0)
    text_rows = text_rows[text_rows > 80]  # below the camera line (its values are 200/0)
    assert line_rows.size >= 20  # the processed line, stretched to its height
    assert text_rows.size and 0 < text_rows[0] - line_rows[-1] < 40


def test_video_frame_uses_its_area(tmp_path):
    """The frame of a real run: under 10 % black (73 % with the old layout)."""
    r = drive(EXAMPLES / "line_follower.py", video=tmp_path / "v.mp4", time_limit_s=1.0)
    assert r.outcome == "timeout"
    cap = cv2.VideoCapture(str(tmp_path / "v.mp4"))
    fractions = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        fractions.append(float(np.mean(frame.max(axis=2) < 16)))
    cap.release()
    assert len(fractions) >= 25 and max(fractions) < 0.10, max(fractions)


def test_camera_rates_are_capped_at_30_video_fps(tmp_path):
    rec = VideoRecorder(tmp_path / "v.mp4", camera_fps=200.0, render=lambda pose: np.zeros((8, 8), np.uint8))
    assert rec.every == 7 and rec.fps == pytest.approx(200 / 7)
    for k in range(15):
        rec.frame_boundary(k, k / 200, Pose2(), dict(speed=0, steer=0, speed_cmd=0, steer_cmd=0,
                                                     lap=0, off_track=False))
    assert rec.close() == tmp_path / "v.mp4"
    assert _frames(tmp_path / "v.mp4")[0] == 3  # frames 0, 7, 14
    for name, kw, every in (("w.mp4", {}, 2), ("x.mp4", {"max_fps": 60.0}, 1)):
        rec = VideoRecorder(tmp_path / name, camera_fps=60.0 if every == 2 else 50.0, render=None, **kw)
        assert rec.every == every
        rec.discard()  # (its threads end: a later test of this process may count threads)


def _numbered(k: int) -> np.ndarray:
    """A camera image showing ``k`` (0..255) in binary: eight 16-pixel stripes, white for a 1."""
    bits = np.repeat([(k >> b) & 1 for b in range(8)], 16).astype(np.uint8) * 255
    return np.tile(bits, (128, 1))


def _numbers_shown(path) -> list[int]:
    """The number of :func:`_numbered` each frame of the video at ``path`` shows."""
    x0, _, _, y1 = Layout.for_frame((128, 128), None).camera
    cap = cv2.VideoCapture(str(path))
    shown = []
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        px = [frame[y1 // 2, x0 + (16 * b + 8) * 3].mean() for b in range(8)]
        shown.append(sum(1 << b for b, v in enumerate(px) if v > 128))
    cap.release()
    return shown


@pytest.mark.parametrize("period_s", [0.0195, 0.1, 0.0045], ids=["free-running", "slow", "fast"])
def test_each_video_frame_shows_the_camera_frame_of_its_time(tmp_path, period_s):
    """The video (25 fps: a 50 fps camera's at the start) plays in simulated time whatever the
    camera's period: its frame j shows the latest camera frame at or before j / 25 s - frames
    one exposure apart (19.5 ms, as a kit's free-running camera gives them; the video took every
    second one, 2.5 % too many: it played slow), slower ones held, faster ones left out. The
    frames' times are whole 2-ms steps, as the clock gives them."""
    rec = VideoRecorder(tmp_path / "v.mp4", camera_fps=50.0, render=None)
    state = dict(speed=0, steer=0, speed_cmd=0, steer_cmd=0, lap=0, off_track=False)
    times = [round(k * period_s / 0.002) * 0.002 for k in range(int(2.0 / period_s) + 1)]
    for k, t in enumerate(times):
        rec.frame_boundary(k, t, Pose2(), state)
        rec.note_image(_numbered(k % 256), -1)
    assert rec.close() == tmp_path / "v.mp4"
    expected = [max(k for k, t in enumerate(times) if t <= j / 25 + 1e-9) % 256
                for j in range(int(times[-1] * 25 + 1e-9) + 1)]
    assert _numbers_shown(tmp_path / "v.mp4") == expected


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
@pytest.mark.parametrize("kit, source", [("tfc", "main.c"), ("tfc-mbed", "mbed/main.cpp")])
def test_a_free_running_kits_video_plays_in_the_runs_simulated_time(tmp_path, kit, source):
    """The TFC kits' example firmware: images one 19.5-ms exposure apart (the PIT's, the servo
    frame's: 51.3 a second), a video of 25 fps whose every frame is 40 ms of simulated time: as
    long as the run, to a frame (it took every second image: 2.5 % longer than the run)."""
    import av

    from simrunner.run.native import build_program

    program = build_program([str(EXAMPLES / "firmware" / source)], kit=kit)
    r = drive(program, time_limit_s=6.0, video=tmp_path / "v.mp4")
    assert r.outcome == "timeout", r.message
    t_s = np.asarray(r.log.t_s)
    assert (t_s[-1] - t_s[-101]) / 100 == pytest.approx(0.0195)  # the last 100 images
    with av.open(str(tmp_path / "v.mp4")) as video:
        stream = video.streams.video[0]
        frames, duration_s = stream.frames, float(stream.duration * stream.time_base)
        rate = stream.average_rate
    assert rate == 25 and frames == int(t_s[-1] * 25 + 1e-9) + 1, (frames, t_s[-1])
    assert abs(duration_s - r.sim_time_s) <= 1 / 25 + 1e-9, (duration_s, r.sim_time_s)  # (one frame)


def test_a_left_out_frame_does_not_change_the_frame_before_it(tmp_path):
    """At 50 fps the video keeps frames 0, 2, ..: frame 0 shows its own image and text, not
    those the controller got in frame 1; frame 2 (no image) shows the line of frame 1."""
    rec = VideoRecorder(tmp_path / "v.mp4", camera_fps=50.0, render=lambda pose: np.full((128, 128), 90, np.uint8))
    state = dict(speed=0, steer=0, speed_cmd=0, steer_cmd=0, lap=0, off_track=False)
    white, black = np.full((128, 128), 255, np.uint8), np.zeros((128, 128), np.uint8)
    for k, img in enumerate((white, black, None)):
        rec.frame_boundary(k, k / 50, Pose2(), state)
        if img is not None:
            rec.note_image(img, -1)
    assert rec.close() == tmp_path / "v.mp4"
    cap = cv2.VideoCapture(str(tmp_path / "v.mp4"))
    frames = [cap.read()[1] for _ in range(2)]
    layout = Layout.for_frame((128, 128), None)
    x0 = layout.middle[0] + 8
    assert frames[0][200, 200].min() > 240 and frames[0][40, x0 + 100].min() > 240  # frame 0: white
    assert abs(int(frames[1][200, 200].mean()) - 90) < 8  # frame 2: the rendered view ...
    assert frames[1][40, x0 + 100].max() < 15  # ... and the last line noted (frame 1's, black)


def _features(k: int):
    """Pixy2 features of frame ``k`` (a vector, an intersection, a barcode; at the grid's edges)."""
    from types import SimpleNamespace as NS

    vec = NS(m_index=1, m_x0=0, m_y0=51, m_x1=78 - k, m_y1=0)
    return (NS(vectors=[vec], intersections=[NS(m_x=(k * 6) % 79, m_y=51)], barcodes=[NS(m_x=78, m_y=(k * 4) % 52, m_code=k)]),
            1, 79, 52)


def test_a_composer_draws_what_compose_draws_frame_by_frame():
    """The background drawn once (the path added to it frame by frame) and the frame kept from
    one to the next (what a frame drew restored from the background) give the frames that
    composing each frame from scratch gives: with text, processed lines, the Pixy2's overlay and
    objects on the track coming and going."""
    from worlds.solids import Solid

    track = load_track(EXAMPLES / "kit_S.txt")
    h, w = np.asarray(track.raster.image).shape
    layout = Layout.for_frame((128, 128), w / h)
    x0, y0, x1, y1 = layout.top
    composer = Composer(layout, TrackView(track.raster, x1 - x0, y1 - y0), 2)
    fresh = TrackView(track.raster, x1 - x0, y1 - y0)
    p = track.start
    box = Solid("box", p.x_m + 0.5, p.y_m + 0.1, 0.2, 0.1, 0.1, yaw_rad=0.4)
    for k in range(16):
        pose = Pose2(p.x_m + 0.05 * k, p.y_m + 0.01 * k * k, p.yaw_rad + 0.02 * k)
        state = dict(speed=1.0, steer=0.1, speed_cmd=1.2, steer_cmd=0.1, lap=k // 6, off_track=k in (5, 6))
        if 3 <= k < 7:
            state["solids"] = (box,)
        rec = _record(frame=k, pose=pose, line_row=(20 + 7 * k) % 128, state=state,
                      text=(f"text {k}" * (1 + k % 4),) * (k % 5),
                      lines=np.full((k % 3, 128), 15 * k, np.uint8) if k % 3 else None,
                      pixy2=_features(k) if k % 4 in (1, 2) else None)
        a, b = composer.frame(rec), compose(rec, fresh, 2, layout=layout)
        assert np.array_equal(a, b), k
    assert np.any(a != compose(_record(), None, 2, layout=layout))  # the map and its path


def test_video_path_must_be_mp4(tmp_path):
    with pytest.raises(SimError, match=r"\.mp4"):
        VideoRecorder(tmp_path / "v.avi", camera_fps=50, render=None)


RACEWAY = Path(__file__).resolve().parents[2] / "shared" / "tracks" / "nxp_raceway"


@pytest.mark.skipif(not RACEWAY.is_dir(), reason="../shared/tracks is absent")
def test_the_video_is_the_same_every_run_while_the_exposure_changes(tmp_path):
    """The line follower's auto exposure changes the exposure on the raceway while the video's
    thread draws the frames the controller took no image in: each is drawn at the exposure in
    force when the frame began (it read the exposure when the thread got to it: 14-22 frames
    of the camera panel differed between runs)."""
    follower = Path(__file__).resolve().parents[1] / "examples" / "line_follower.py"
    videos = []
    for k in range(2):
        drive(follower, track=RACEWAY, video=tmp_path / f"v{k}.mp4")
        videos.append((tmp_path / f"v{k}.mp4").read_bytes())
    assert videos[0] == videos[1]


def test_h264_writer_is_faithful_deterministic_and_plays_as_h264(tmp_path):
    """The encoder: H.264 that OpenCV reads back, each frame within 35 dB of what was written
    (the panels' text stays legible), the same frames give the same bytes, a 33.3 fps camera's
    rate kept; a frame of the wrong size is refused before it reaches the encoder."""
    from simrunner.reports.video_encoder import H264Writer

    rng = np.random.default_rng(3)
    base = np.full((FRAME_H, FRAME_W, 3), 40, np.uint8)
    frames = []
    for i in range(12):
        f = base.copy()
        cv2.putText(f, f"time {i * 0.03:.3f} s", (20, 40 + 8 * i), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (235, 235, 235), 1)
        f[300:340, 100 + 10 * i:200 + 10 * i] = (60, 200, 60)
        cam = np.linspace(30, 220, 384)[None, :] + rng.normal(0, 3, (384, 384))  # a camera image with noise
        f[0:384, 0:384] = np.clip(cam, 0, 255).astype(np.uint8)[..., None]
        frames.append(f)
    paths = [tmp_path / "a.mp4", tmp_path / "b.mp4"]
    for p in paths:
        w = H264Writer(p, 100 / 3, FRAME_W, FRAME_H)
        for f in frames:
            w.write(f)
        w.close()
        w.close()  # a second close does nothing
    assert paths[0].read_bytes() == paths[1].read_bytes()
    cap = cv2.VideoCapture(str(paths[0]))
    assert int(cap.get(cv2.CAP_PROP_FOURCC)).to_bytes(4, "little") in (b"avc1", b"h264")
    assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(100 / 3, rel=1e-3)
    got = []
    while True:
        ok, g = cap.read()
        if not ok:
            break
        got.append(g)
    assert len(got) == len(frames)
    assert min(cv2.PSNR(f, g) for f, g in zip(frames, got)) > 35.0
    w = H264Writer(tmp_path / "c.mp4", 25, FRAME_W, FRAME_H)
    with pytest.raises(ValueError, match="expected"):
        w.write(np.zeros((FRAME_H, FRAME_W), np.uint8))
    w.close()


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_a_full_disk_is_one_line_naming_the_video_not_a_crash(tmp_path):
    """A video whose writes fail (its file on a full disk: /dev/full) raises SimError with the
    OS's reason at the write and every later one, and closes without muxing more (PyAV 18
    crashes on that); drive says so in one line and keeps the CSV rows written."""
    from click.testing import CliRunner

    from simrunner.cli import main as cli
    from simrunner.reports.video_encoder import H264Writer

    (tmp_path / "a.mp4").symlink_to("/dev/full")
    w = H264Writer(tmp_path / "a.mp4", 25, FRAME_W, FRAME_H)
    frame = np.zeros((FRAME_H, FRAME_W, 3), np.uint8)
    with pytest.raises(SimError, match="No space left on device"):
        for i in range(60):
            w.write(frame + i)
    with pytest.raises(SimError, match="No space left on device"):
        w.write(frame)
    w.close()  # (already reported)
    (tmp_path / "run.partial.mp4").symlink_to("/dev/full")
    res = CliRunner().invoke(cli, ["drive", str(EXAMPLES / "line_follower.py"), "--video", str(tmp_path / "run.mp4"),
                                   "--csv", str(tmp_path / "run.csv")])
    assert res.exit_code != 0 and "Traceback" not in res.output
    assert f"{tmp_path / 'run.mp4'}: cannot write the video (No space left on device)" in res.output
    assert len((tmp_path / "run.csv").read_text().splitlines()) > 10
    assert not (tmp_path / "run.partial.mp4").is_symlink() and not (tmp_path / "run.mp4").exists()


def test_a_video_path_that_cannot_be_written_fails_before_the_run(tmp_path):
    """PyAV opens its file at the first frame: the writer opens it itself, so a path that cannot
    be written is one line before the run starts (a read-only folder), not a run stopped midway."""
    from simrunner.reports.video_encoder import H264Writer

    ro = tmp_path / "ro"
    ro.mkdir()
    (ro / "v.mp4").mkdir()  # a folder where the file should be (as a read-only place, also as root)
    with pytest.raises(SimError, match=r"v.mp4: cannot write the video \(Is a directory\)"):
        H264Writer(ro / "v.mp4", 25, FRAME_W, FRAME_H)


def test_without_libx264_the_video_is_mpeg4_and_without_any_encoder_one_line(tmp_path, monkeypatch):
    """PyAV built without libx264 (an LGPL FFmpeg): MPEG-4 Part 2, still faithful; with none of
    the encoders: one SimError line and no file left."""
    import simrunner.reports.video_encoder as enc

    monkeypatch.setattr(enc, "ENCODERS", (("no_such_encoder", {}),) + enc.ENCODERS[1:])
    frames = [np.full((FRAME_H, FRAME_W, 3), 30 + 20 * i, np.uint8) for i in range(5)]
    for f in frames:
        cv2.putText(f, "speed 1.234 m/s", (40, 300), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (235, 235, 235), 1, cv2.LINE_AA)
    w = enc.H264Writer(tmp_path / "a.mp4", 25, FRAME_W, FRAME_H)
    assert w.codec == "mpeg4"
    for f in frames:
        w.write(f)
    w.close()
    cap = cv2.VideoCapture(str(tmp_path / "a.mp4"))
    got = [cap.read()[1] for _ in frames]
    assert min(cv2.PSNR(f, g) for f, g in zip(frames, got)) > 35.0
    monkeypatch.setattr(enc, "ENCODERS", (("no_such_encoder", {}),))
    with pytest.raises(SimError, match="none of the encoders no_such_encoder"):
        enc.H264Writer(tmp_path / "b.mp4", 25, FRAME_W, FRAME_H)
    assert not (tmp_path / "b.mp4").exists()
