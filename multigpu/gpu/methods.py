"""How a rank makes its region's pixels (``--subfrustum``): the methods, the GL limits that bound
each, and the choice between them (``render.RegionRenderer``; docs/ACCURACY.md measures them)."""

from __future__ import annotations

from multigpu.errors import InputError

METHODS = ("auto", "viewport", "scissor", "offaxis")


def gl_limits(ctx) -> dict:
    """The GL limits that bound each sub-frustum method (pixels)."""
    info = ctx.info
    vw, vh = info.get("GL_MAX_VIEWPORT_DIMS", (16384, 16384))
    lo, _ = info.get("GL_VIEWPORT_BOUNDS_RANGE", (-32768, 32767))
    return {"viewport": (int(vw), int(vh)), "bounds_low": int(lo),
            "renderbuffer": int(info.get("GL_MAX_RENDERBUFFER_SIZE", 16384))}


def choose_method(method: str, size: tuple[int, int], limits: dict) -> str:
    """The sub-frustum method to use for a ``size`` display, or a clear error.

    ``scissor`` (bit-exact): full-display framebuffer scissored to the region; needs W, H
    within GL_MAX_RENDERBUFFER_SIZE and costs W*H*8 bytes per rank. ``viewport``:
    region-sized framebuffer, the full-display viewport shifted by the region's origin; needs
    W, H within GL_MAX_VIEWPORT_DIMS and the shift within GL_VIEWPORT_BOUNDS_RANGE; the
    shifted viewport transform rounds differently, so a few edge pixels per frame differ.
    ``offaxis``: region-sized framebuffer, the region's own off-axis frustum; any display size;
    not bit-exact either. docs/ACCURACY.md measures all three. ``auto``: the first that fits,
    in that order.
    """
    if method not in METHODS:
        raise InputError.of("subfrustum", f"must be one of {', '.join(METHODS)}, got '{method}'")
    W, H = size
    fits_viewport = W <= limits["viewport"][0] and H <= limits["viewport"][1] and max(W, H) <= -limits["bounds_low"]
    fits_scissor = max(W, H) <= limits["renderbuffer"]
    if method == "auto":
        return "scissor" if fits_scissor else "viewport" if fits_viewport else "offaxis"
    if method == "viewport" and not fits_viewport:
        raise InputError.of("subfrustum", f"viewport: a {W}x{H} display exceeds this GL's maximum viewport "
                         f"{limits['viewport'][0]}x{limits['viewport'][1]} (use offaxis or auto)")
    if method == "scissor" and not fits_scissor:
        raise InputError.of("subfrustum", f"scissor: a {W}x{H} display exceeds this GL's maximum framebuffer "
                         f"{limits['renderbuffer']} pixels per side (use viewport, offaxis or auto)")
    return method


__all__ = ["METHODS", "choose_method", "gl_limits"]
