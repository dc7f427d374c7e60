"""The ``--obs camera`` options of a real sensor's errors, shared by `run` and `data generate`."""

from __future__ import annotations

import typer


def depth_noise_option():
    return typer.Option(0.0, min=0.0, help="Camera: depth noise, the standard deviation in m at 1 m "
                                           "(it grows with depth squared) [default: none].")


def depth_holes_option():
    return typer.Option(0.0, min=0.0, max=0.99, help="Camera: share of pixels with no depth, at random.")


def edge_holes_option():
    return typer.Option(False, help="Camera: no depth at depth edges (a door's rim), as real sensors lose it.")


def seg_noise_option():
    return typer.Option(0, min=0, help="Camera: segmentation errors within this many pixels of a part "
                                       "boundary (each such pixel takes its neighbour's label half the time).")


def camera_noise_settings(obs: str, depth_noise: float, depth_holes: float, edge_holes: bool,
                          seg_noise_px: int) -> dict:
    """The env's ``camera_noise`` dict ({} for a clean camera); BadParameter when set without a camera."""
    from wpbench.sim.camera_noise import CameraNoise

    try:
        noise = CameraNoise(depth_std=depth_noise, hole_fraction=depth_holes, edge_holes=edge_holes,
                            boundary_px=seg_noise_px)
    except ValueError as err:
        raise typer.BadParameter(str(err)) from None
    if obs != "camera" and not noise.is_clean:
        raise typer.BadParameter("--depth-noise, --depth-holes, --edge-holes and --seg-noise-px need --obs camera")
    return noise.settings()
