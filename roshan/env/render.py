"""What the vector envs show when rendered: env 0's frame, drawn by the render kernels on first use."""

import numpy as np

from roshan.kernels.render import DroneOverlay, FrameRenderer, drone_overlay


class EnvZeroFrames:
    """``render()`` of the vector envs: env 0's land cover, fire and drones through the raster backend, built on
    the first call (rendering is optional, and the renderer compiles kernels)."""

    def __init__(self, drones):
        self.drones = drones
        self._renderer: FrameRenderer | None = None
        self._overlay: DroneOverlay | None = None

    def render(self) -> np.ndarray:
        if self._renderer is None:
            self._renderer = FrameRenderer(self.drones.fire, backend="raster")
            self._overlay = drone_overlay(self.drones)
        return self._renderer.render(overlay=self._overlay)

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
