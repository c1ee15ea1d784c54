"""A robot's description for viewers: a URDF of its footprint and drive wheels from the run's geometry (docs/ros.md).

RViz and Foxglove draw a robot from ``/robot_description`` and place its links by ``/tf`` and ``/tf_static``. The
wheels sit where the physics puts them (radius R, at y = +-L from the axle midpoint); the chassis, wheel width and
caster sphere are drawn to scale from R and L but are no part of the model (they are for the eye, nothing reads them).
"""

from __future__ import annotations

from dataclasses import dataclass
from xml.sax.saxutils import quoteattr

from .messages import WHEEL_JOINTS

#: the links of the description besides the base frame: the chassis at axle height, the wheels, the caster
CHASSIS_LINK = "chassis_link"
WHEEL_LINKS = ("wheel_right_link", "wheel_left_link")
CASTER_LINK = "caster_link"
WHEEL_WIDTH = 0.5  #: drawn wheel width over R (a TurtleBot3's is 0.018 m at R = 0.033 m)


@dataclass(frozen=True)
class Fixed:
    """A fixed joint's transform from the base frame: translation [m], the child link (what /tf_static carries)."""

    child: str
    x: float
    y: float
    z: float


def fixed_links(*, wheel_radius: float, caster: float | None) -> tuple[Fixed, ...]:
    """The fixed joints of :func:`robot_urdf`: the chassis at the axle's height, and the caster (body x ``caster``
    [m], on the floor's side of the chassis) when the run's plant has one."""
    links = [Fixed(CHASSIS_LINK, 0.0, 0.0, wheel_radius)]
    if caster is not None:
        links.append(Fixed(CASTER_LINK, caster, 0.0, wheel_radius / 2.0))
    return tuple(links)


def wheel_offsets(*, wheel_radius: float, half_axle: float) -> dict[str, tuple[float, float, float]]:
    """Each wheel link's origin in the base frame: (0, -L, R) right, (0, L, R) left."""
    return {WHEEL_LINKS[0]: (0.0, -half_axle, wheel_radius), WHEEL_LINKS[1]: (0.0, half_axle, wheel_radius)}


def robot_urdf(name: str, base_frame: str, *, wheel_radius: float, half_axle: float, caster: float | None) -> str:
    """The URDF of a differential-drive robot whose base frame ``base_frame`` is the axle midpoint on the floor.

    The wheel joints are continuous, about the wheel's axis (body y), named as ``/joint_states`` names them
    (:data:`~ddtrack.ros.messages.WHEEL_JOINTS`), so a ``robot_state_publisher`` fed the bag's joint states would
    place the wheels as the bag's ``/tf`` does."""
    width = WHEEL_WIDTH * wheel_radius
    chassis = (2.0 * half_axle, 2.0 * half_axle - 2.0 * width, wheel_radius)  # between the wheels, as tall as R
    parts = [
        f"<robot name={quoteattr(name)}>",
        f"  <link name={quoteattr(base_frame)}/>",
        _link(CHASSIS_LINK, f'<box size="{_xyz(*chassis)}"/>', "0 0 0"),
    ]
    for link, joint, origin in zip(
        WHEEL_LINKS, WHEEL_JOINTS, wheel_offsets(wheel_radius=wheel_radius, half_axle=half_axle).values(), strict=True
    ):
        cylinder = f'<cylinder radius="{wheel_radius!r}" length="{width!r}"/>'
        parts.append(_link(link, cylinder, "1.5707963267948966 0 0"))  # a URDF cylinder's axis is z: turned onto y
        parts.append(_joint(joint, "continuous", base_frame, link, origin, axis="0 1 0"))
    for fixed in fixed_links(wheel_radius=wheel_radius, caster=caster):
        if fixed.child == CASTER_LINK:
            parts.append(_link(CASTER_LINK, f'<sphere radius="{wheel_radius / 2.0!r}"/>', "0 0 0"))
        parts.append(_joint(f"{fixed.child}_joint", "fixed", base_frame, fixed.child, (fixed.x, fixed.y, fixed.z)))
    parts.append("</robot>")
    return "\n".join(parts) + "\n"


def _xyz(x: float, y: float, z: float) -> str:
    return f"{x!r} {y!r} {z!r}"


def _link(name: str, geometry: str, rpy: str) -> str:
    return (
        f'  <link name={quoteattr(name)}>\n    <visual>\n      <origin xyz="0 0 0" rpy="{rpy}"/>\n'
        f"      <geometry>{geometry}</geometry>\n    </visual>\n  </link>"
    )


def _joint(
    name: str, kind: str, parent: str, child: str, origin: tuple[float, float, float], axis: str | None = None
) -> str:
    lines = [
        f"  <joint name={quoteattr(name)} type={quoteattr(kind)}>",
        f"    <parent link={quoteattr(parent)}/>",
        f"    <child link={quoteattr(child)}/>",
        f'    <origin xyz="{_xyz(*origin)}" rpy="0 0 0"/>',
    ]
    if axis is not None:
        lines.append(f'    <axis xyz="{axis}"/>')
    return "\n".join([*lines, "  </joint>"])
