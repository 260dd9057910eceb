"""The ego camera of a scenario: intrinsics and mount (:class:`CameraSpec`).

Only a vision ego reads it (``ego: {policy: vision_pilotnet}``); the defaults
are PilotNet's 66 x 200 image from a windscreen camera::

    camera: {width: 200, height: 66, hfov: 60.0, mount_height: 1.4,
             pitch: 5.0, forward: 1.0}
"""

from __future__ import annotations

from pydantic import Field

from avrisk.scenario.scene import SpecModel

__all__ = ["CameraSpec"]


class CameraSpec(SpecModel):
    """A pinhole front camera on the ego (see :class:`avrisk.render.CameraModel`)."""

    width: int = Field(200, ge=1, le=4096, description="Image width [pixels].")
    height: int = Field(66, ge=1, le=4096, description="Image height [pixels].")
    hfov: float = Field(
        60.0, gt=0.0, lt=170.0, description="Horizontal field of view [deg]."
    )
    mount_height: float = Field(
        1.4, gt=0.0, le=10.0, description="Camera height above the ground [m]."
    )
    pitch: float = Field(
        5.0, gt=-45.0, lt=45.0, description="Downward pitch of the optical axis [deg]."
    )
    forward: float = Field(
        1.0,
        ge=-15.0,
        le=15.0,
        description="Camera position ahead of the ego's centre [m].",
    )
