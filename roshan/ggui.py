"""The process's one offscreen GGUI window (``ti.ui.Window``), shared by every GGUI frame renderer.

Taichi 1.7 crashes (at ``destroy`` or at interpreter exit) when two GGUI windows are alive at once, so the
process holds at most one: users of the same size share it, and a user of another size replaces it (about 0.2 s
to open). The window is destroyed when its last user releases it.
"""

import os
import tempfile

from roshan import runtime, taichi_patches

ti = taichi_patches.import_taichi()  # patched before Taichi defines its own kernels, whoever imports this first

WINDOW_TITLE = "ROSHAN-Taichi"


def _state() -> dict:
    """The window, its size, the Taichi runtime it belongs to and its users. The runtime is kept (not its id) so a
    re-initialised Taichi can never look like the one the window belongs to."""
    return runtime.for_this_process("ggui window", lambda: {"window": None, "res": None, "runtime": None, "users": 0})


def _open_window(res: tuple[int, int]):
    """A new offscreen GGUI window of ``res = (width, height)``; raises if GGUI/Vulkan is unavailable."""
    window = ti.ui.Window(WINDOW_TITLE, res, show_window=False)
    _state().update(window=window, res=tuple(res), runtime=ti.lang.impl.get_runtime())
    return window


def _close_window() -> None:
    if _state()["window"] is not None:
        _destroy_elsewhere(_state()["window"])
    _state().update(window=None, res=None, runtime=None)


def _destroy_elsewhere(window) -> None:
    """Destroy ``window`` with a scratch folder as the working directory: Dear ImGui (inside GGUI) writes its
    window layout to ``./imgui.ini`` when its context is destroyed (measured with Taichi 1.7.4: never while frames
    render, nor at exit with the window open), and Taichi offers no way to turn that off. The user's folder stays
    clean. The working directory is process-wide, but only for the instant of the destroy."""
    with tempfile.TemporaryDirectory(prefix="roshan_ggui_") as scratch:
        cwd = os.getcwd()
        os.chdir(scratch)
        try:
            window.destroy()
        finally:
            os.chdir(cwd)


def acquire_window(res: tuple[int, int], held):
    """The process's one GGUI window, sized ``res``; ``held`` is the window the caller already counts as a user of.

    Replaces the window when the size differs or when Taichi was re-initialised since it was opened.
    """
    if _state()["res"] != tuple(res) or _state()["runtime"] is not ti.lang.impl.get_runtime():
        _close_window()
        _open_window(res)
    if held is None:
        _state()["users"] += 1
    return _state()["window"]


def release_window() -> None:
    _state()["users"] = max(0, _state()["users"] - 1)
    if _state()["users"] == 0:
        _close_window()


def ggui_available() -> bool:
    """Whether an offscreen GGUI window can be opened in this process (opens the shared window if none is open)."""
    if _state()["window"] is not None:
        return True
    try:
        _open_window((16, 16))
        return True
    except Exception:  # any failure to open a window means no usable GGUI here
        return False


def open_shown_window(res: tuple[int, int], title: str = WINDOW_TITLE):
    """A visible GGUI window of ``res = (width, height)`` (``roshan watch``); raises where none can open.

    The shared offscreen window is closed first when nobody uses it (two live windows crash Taichi 1.7).
    """
    if _state()["window"] is not None:
        if _state()["users"] > 0:
            raise RuntimeError("an offscreen GGUI window is in use; close its renderers before opening a shown one")
        _close_window()
    return ti.ui.Window(title, tuple(res), show_window=True, vsync=False)
