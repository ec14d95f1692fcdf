"""A borderless glfw window showing one rank's tile, bit for bit.

glfw (a small, well-kept C library with one job: windows, contexts and input) opens the window
at the tile's place on its X display and makes a GL 4.3 core context, which the rank also
renders in (an EGL context and a GLX window cannot be current in turn in one process with Mesa:
``BadAccess`` on ``glXMakeCurrent``). ``show`` uploads the composed tile into a texture and
blits it 1:1 into the back buffer (no filtering, no colour conversion: the screen holds the
composite's bytes); ``swap`` swaps with vsync where the driver has it (tear-free on a monitor;
Xvfb returns at once). Escape or a window closed by the user or a window manager ends the run
after the current frame (``poll``).
"""

from __future__ import annotations

import os
import time

import numpy as np

from multigpu.errors import InputError

#: hint that tells the user how to fix a missing or refused X display
X_HELP = ("start an X server there (e.g. Xvfb for testing), set DISPLAY, give the rank a display in the "
          "wall file, or run --present headless")


#: glfw windows open in this process (glfw is terminated when the last one closes)
_OPEN = [0]


class Window:
    """One rank's tile window (or rank 0's monitor): ``context`` is the moderngl context of
    the window, which the rank renders in."""

    mode = "window"

    def __init__(self, rank: int, tile_size: tuple[int, int], position: tuple[int, int], display: str | None,
                 where: str, title: str | None = None, vsync: bool = True, fullscreen: bool = False,
                 origin: tuple[int, int] = (0, 0)):
        try:
            import glfw
        except Exception as exc:  # the wheel bundles libglfw; a source install may lack it
            raise InputError.of("present", f"window needs glfw with its library (pip install glfw; "
                             f"Debian: apt install libglfw3): {exc.__class__.__name__}: {exc}") from None
        import moderngl

        self.glfw = glfw
        self.window = None
        self.counted = False
        self.reason: str | None = None
        errors: list[str] = []
        glfw.set_error_callback(lambda code, text: errors.append(text.decode() if isinstance(text, bytes) else text))
        if display:
            os.environ["DISPLAY"] = display
        name = os.environ.get("DISPLAY")
        if not name:
            raise InputError.of("present", f"window: rank {rank} has no X display ($DISPLAY is not set, {where}); "
                                           f"{X_HELP}")
        if not glfw.init():
            why = errors[-1] if errors else "glfw could not initialise"
            raise InputError.of("present", f"window: rank {rank} cannot open X display '{name}' ({where}): {why}; "
                                           f"{X_HELP}")
        _OPEN[0] += 1
        self.counted = True
        self.controls = None
        try:
            for hint, value in ((glfw.DECORATED, False), (glfw.RESIZABLE, False), (glfw.VISIBLE, False),
                                (glfw.AUTO_ICONIFY, False), (glfw.FOCUS_ON_SHOW, False),
                                (glfw.CONTEXT_VERSION_MAJOR, 4), (glfw.CONTEXT_VERSION_MINOR, 3),
                                (glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)):
                glfw.window_hint(hint, value)
            tw, th = tile_size
            # full screen as a borderless window over the whole screen, above the others: no video
            # mode change, so a mode the tile does not match is caught by ``wall check`` instead
            glfw.window_hint(glfw.FLOATING, bool(fullscreen))
            self.window = glfw.create_window(tw, th, title or f"multigpu tile {rank}", None, None)
            if not self.window:
                why = errors[-1] if errors else "no window"
                raise InputError.of("present", f"window: rank {rank} cannot open a {tw}x{th} GL 4.3 window on "
                                 f"'{name}' ({where}): {why}; {X_HELP}")
            at = origin if fullscreen else position  # ``origin``: where a full-screen output starts
            glfw.set_window_pos(self.window, int(at[0]), int(at[1]))
            glfw.show_window(self.window)
            glfw.make_context_current(self.window)
            glfw.swap_interval(1 if vsync else 0)
            glfw.set_key_callback(self.window, self._on_key)
            self.context = moderngl.create_context(require=430)
            self.texture = self.context.texture((tw, th), 3, alignment=1)
            self.texture.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self.source = self.context.framebuffer(color_attachments=[self.texture])
            self.display = name
        except BaseException:
            self.close()
            raise

    def _on_key(self, window, key, scancode, action, mods) -> None:
        if key == self.glfw.KEY_ESCAPE and action == self.glfw.PRESS:
            self.reason = "escape key"
            self.glfw.set_window_should_close(window, True)
        elif self.controls is not None:
            self.controls.on_key(window, key, scancode, action, mods)

    def take_input(self, controls) -> None:
        """Send this window's keys and mouse to ``controls`` (rank 0's windows)."""
        self.controls = controls
        controls.attach_mouse(self.window)

    def current(self) -> None:
        """Make this window's GL context current (a process with a monitor has two)."""
        self.glfw.make_context_current(self.window)

    def show(self, tile: np.ndarray) -> None:
        self.texture.write(np.ascontiguousarray(tile))
        screen = self.context.screen
        screen.scissor = None  # the renderer's scissor would clip the blit
        screen.use()
        self.context.copy_framebuffer(screen, self.source)

    def swap(self) -> float:
        self.glfw.swap_buffers(self.window)
        return time.time()

    def poll(self) -> str | None:
        self.glfw.poll_events()
        if self.glfw.window_should_close(self.window):
            return self.reason or "window closed"
        return None

    def close(self) -> None:
        if self.window is not None:
            self.glfw.destroy_window(self.window)
            self.window = None
        if self.counted:
            self.counted = False
            _OPEN[0] -= 1
            if _OPEN[0] == 0:
                self.glfw.terminate()
