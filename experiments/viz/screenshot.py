"""Headless screenshots of ``.rrd`` files: the default blueprint rendered by ``rerun --headless``."""

from __future__ import annotations

import os
import shutil
import socket
import sys
import tempfile
import time

from experiments.viz.style import TIMELINE


def screenshot_rrd(rrd_path: str | os.PathLike, png_path: str | os.PathLike, *, time_s: float | None = None,
                   settle_s: float = 3.0) -> str:
    """Render an ``.rrd`` with its default blueprint in a headless Rerun viewer and save a PNG.

    Spawns ``rerun --headless`` (the viewer binary of the installed rerun-sdk) on a free port,
    opens the file, moves the time cursor to ``time_s`` [s] on the ``time`` timeline, waits
    ``settle_s`` [s] for the views to load and saves a 1920 x 1080 screenshot
    (``rerun.experimental.ViewerClient``, rerun-sdk 0.41). About 10 s on a CPU.

    Needs a graphics adapter: a GPU, or on Linux without one Mesa's lavapipe Vulkan driver
    (Debian/Ubuntu package ``mesa-vulkan-drivers``); ``WGPU_BACKEND`` defaults to ``vulkan`` on
    Linux.

    Returns:
        the PNG path.

    Raises:
        FileNotFoundError: no such ``.rrd``.
        RuntimeError: no ``rerun`` executable, no graphics adapter, or the viewer failed.
    """
    rrd_path = os.path.abspath(os.fspath(rrd_path))
    png_path = os.path.abspath(os.fspath(png_path))
    if not os.path.exists(rrd_path):
        raise FileNotFoundError(f"no Rerun file at {rrd_path!r}")
    exe = shutil.which("rerun") or os.path.join(os.path.dirname(sys.executable), "rerun")
    if not os.path.exists(exe):
        raise RuntimeError("no 'rerun' viewer executable found (it comes with rerun-sdk; put its bin/ on PATH)")
    try:
        from rerun.experimental import ViewerClient  # lazy: rerun
    except ImportError as exc:  # pragma: no cover - rerun-sdk < 0.41
        raise RuntimeError(f"this rerun-sdk has no headless viewer client: {exc}") from None
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env_keys = {}
    if sys.platform.startswith("linux"):
        env_keys = {"WGPU_BACKEND": "vulkan", "XDG_RUNTIME_DIR": tempfile_dir()}
    saved = {k: os.environ.get(k) for k in env_keys}
    for k, v in env_keys.items():
        os.environ.setdefault(k, v)
    viewer = None
    try:
        os.makedirs(os.path.dirname(png_path), exist_ok=True)
        if os.path.exists(png_path):
            os.remove(png_path)
        with _quiet_child_output():
            viewer = ViewerClient.spawn(headless=True, port=port, hide_welcome_screen=True, executable_path=exe)
        viewer.open(rrd_path)
        time.sleep(settle_s / 2)
        if time_s is not None:
            viewer.set_time(TIMELINE, duration=float(time_s), play_state="paused")
        time.sleep(settle_s / 2)
        viewer.save_screenshot(png_path)
    except Exception as exc:  # noqa: BLE001 - the viewer reports many kinds of failure
        raise RuntimeError(f"headless Rerun viewer failed ({type(exc).__name__}: {str(exc)[:300]}); a GPU or "
                           "Mesa's lavapipe Vulkan driver (mesa-vulkan-drivers) is needed") from None
    finally:
        if viewer is not None:
            try:
                viewer.quit()
            except Exception:  # noqa: BLE001 - best effort
                pass
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    if not os.path.exists(png_path):
        raise RuntimeError("the headless Rerun viewer saved no screenshot")
    return png_path


class _quiet_child_output:
    """Point fds 1 and 2 at /dev/null while a child process is spawned (it inherits them), so the
    headless viewer's log lines do not mix with the command's output."""

    def __enter__(self):
        for f in (sys.stdout, sys.stderr):
            try:
                f.flush()
            except Exception:  # noqa: BLE001 - best effort
                pass
        self.saved = [os.dup(1), os.dup(2)]
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 1)
        os.dup2(null, 2)
        os.close(null)
        return self

    def __exit__(self, *exc):
        os.dup2(self.saved[0], 1)
        os.dup2(self.saved[1], 2)
        for fd in self.saved:
            os.close(fd)
        return False


def tempfile_dir() -> str:
    """A private runtime directory for the headless viewer (``XDG_RUNTIME_DIR`` must be 0700)."""
    d = os.path.join(tempfile.gettempdir(), f"sgatwalk-xdg-{os.getuid()}")
    os.makedirs(d, mode=0o700, exist_ok=True)
    return d
