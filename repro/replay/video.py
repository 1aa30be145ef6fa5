"""``repro video RUN_DIR``: an H.264 MP4 replayed from a run's own files (issue 20).

Each frame shows, on the left, an external view of the whole scene (every body of
``scene.json``, posed from the trace row at the frame's time) and, on the right, each
eye-in-hand camera's view rendered at the *logged* camera pose (``<camera>_x .. _qw``; the
camera's frame if the trace has no pose) through the run's own projection matrix, with
the true projections (green rings, ``<prefix><i>_u_true``) and the detections (red
crosses, ``<prefix><i>_u`` where ``_found``) drawn; beneath, a caption with the time, the
playback speed, the phase (a ``phase`` column) and the latest events of ``events.csv``.
Nothing of the experiment's code is used: what an outsider can do with the folder.

The external view is framed automatically (:func:`repro.replay.view.auto_view`; no paper
prescribes a view): it looks at the bounding box of the robots' links and the bodies near
them over the run, from the first of a few directions that shows both; its background (no
body) is drawn light blue-grey so that white links stand out.
"""

from __future__ import annotations

import sys
from pathlib import Path

from repro.replay.frames import FPS, SIZE, Replayer, check_options, check_run_dir
from repro.replay.view import frame_rows

__all__ = ["BITRATE_KBPS", "FPS", "MAX_VIDEO_S", "MIN_VIDEO_S", "SIZE", "Replayer",
           "check_options", "check_run_dir", "frame_rows", "write_video"]

#: ours: the stated bitrate of every video (a 40 s, 960 x 480 replay is ~2 MB).
BITRATE_KBPS = 400
MAX_VIDEO_S = 40.0  # ours: a longer run plays faster (speed = duration / 40 s)
MIN_VIDEO_S = 5.0  # ours: a shorter run plays in slow motion (speed = duration / 5 s)


def write_video(run_dir: Path, out: Path | None = None, *, fps: float = FPS,
                size: tuple[int, int] = SIZE, speed: float | None = None,
                bitrate_kbps: int = BITRATE_KBPS, progress: bool | None = None) -> Path:
    """Replay ``run_dir`` into an H.264 MP4 (default ``<run_dir>/video.mp4``).

    ``speed``: simulated seconds per video second (default: 1; faster so the video lasts at
    most :data:`MAX_VIDEO_S`, slower so it lasts at least :data:`MIN_VIDEO_S`). Every
    argument is checked before anything is written.
    """
    import imageio.v2 as imageio
    import imageio_ffmpeg  # noqa: F401  (its ffmpeg writes the MP4; a clear ImportError)

    run_dir = Path(run_dir)
    check_options(fps, size, speed)
    with Replayer(run_dir, size) as rep:
        t = rep.trace["t"].to_numpy(float)
        duration = float(t[-1] - t[0])
        if speed is None:
            speed = (max(1.0, duration / MAX_VIDEO_S) if duration >= MIN_VIDEO_S
                     else max(duration, 1e-3) / MIN_VIDEO_S)
        rows = frame_rows(t, fps, speed)
        out = Path(out) if out is not None else run_dir / "video.mp4"
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(out.stem + ".partial.mp4")
        bar = None
        if progress if progress is not None else sys.stderr.isatty():
            from tqdm import tqdm

            bar = tqdm(total=len(rows), unit="frame", desc=out.name, leave=False)
        writer = imageio.get_writer(tmp, fps=fps, codec="libx264", bitrate=f"{bitrate_kbps}k",
                                    pixelformat="yuv420p", macro_block_size=16,
                                    ffmpeg_log_level="error")
        try:
            try:
                for r in rows:
                    writer.append_data(rep.frame(r, speed))
                    if bar is not None:
                        bar.update(1)
            finally:
                writer.close()  # waits for ffmpeg: the file is complete (or abandoned) here
            tmp.replace(out)  # a killed replay leaves no half-written video under the name
        finally:
            tmp.unlink(missing_ok=True)
            if bar is not None:
                bar.close()
    return out
