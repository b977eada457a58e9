"""Build the dartpy skeleton of the car from a :class:`vehicle.description.CarDescription`.

Bodies and joints (all numbers from the description; frames as in docs/DESIGN.md):

    chassis      FreeJoint root. Body frame = car body frame: origin at the rear-axle
                 midpoint ON THE GROUND, x forward, y left, z up. Collision/inertia: a box
                 ``length x width x height`` centred ``length/2 - rear_overhang`` ahead of the
                 rear axle at height ``cog_height`` (its moments of inertia times
                 ``effects.inertia_scale``, 1 in the nominal model).
    knuckle_l/r  RevoluteJoint about the chassis z axis at the front wheel centres
                 ``(wheelbase, +-track/2, wheel_radius)``; positive angle = wheel turned left.
    wheel_fl/fr  RevoluteJoint about the knuckle's y axis (the axle), at the knuckle origin.
    wheel_rl/rr  RevoluteJoint about the chassis y axis at ``(0, +-track/2, wheel_radius)``.

A positive wheel joint velocity rolls the car forward (+x): for a wheel of radius r at
rest on the ground, joint speed ``omega`` moves it at ``omega * r``.

Wheel inertia is that of a solid cylinder with its axis on the axle (the body y axis:
moment ``m r^2 / 2`` about y). The wheel COLLISION shape is chosen by ``WheelShape``:

* ``SPHERE`` (default): a sphere of the wheel radius, i.e. a round tyre profile touching
  the ground in one point on the tyre's centre plane. Measured (ODE, 2 ms, default car,
  ``w = v tan(delta) / L``): steady turn radius = L / tan(delta) within 0.01 % and no
  oscillation, ~29k steps/s.
* ``CYLINDER``: a flat tyre of ``wheels.width_m`` (dart's CylinderShape has its axis along
  z, so the shape node is rotated -90 deg about x). ODE gives two contacts per wheel, at
  the two rims; in a turn the rims must scrub, and the rigid over-constrained car goes
  into a ~1.9 s stick-slip cycle (yaw rate +-1.5 %) with the mean radius 2.7-4.8 % too
  large at 0.5 m/s, at ~15k steps/s. Kept for comparison. Masses: ``chassis.mass_kg`` is the total;
the chassis body gets the total minus four wheels and two knuckles
(``KNUCKLE_MASS_FRACTION`` of a wheel each).
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import dartpy as dart
import numpy as np

from vehicle.description import CarDescription, CarDescriptionError
from vehicle.modelling import CHASSIS_MU, KNUCKLE_MASS_FRACTION


WHEEL_NAMES = ("wheel_fl", "wheel_fr", "wheel_rl", "wheel_rr")


class WheelShape(Enum):
    """Collision shape of the tyres (see the module docstring for the measured trade-off)."""

    SPHERE = "sphere"
    CYLINDER = "cylinder"


@dataclass
class CarBody:
    """Handles into one built car skeleton (owned by one ``CarSim``)."""

    skeleton: dart.dynamics.Skeleton
    chassis: dart.dynamics.BodyNode
    free_joint: dart.dynamics.FreeJoint
    knuckle_joints: tuple  # (left, right) RevoluteJoint
    wheel_joints: tuple  # (FL, FR, RL, RR) RevoluteJoint
    wheel_bodies: tuple  # (FL, FR, RL, RR) BodyNode
    wheel_spin_inertia_kgm2: float  # one wheel's moment of inertia about its axle
    total_mass_kg: float


def isometry(translation=(0.0, 0.0, 0.0), rotation: np.ndarray | None = None) -> dart.math.Isometry3:
    tf = dart.math.Isometry3()
    tf.set_identity()
    if rotation is not None:
        tf.set_rotation(np.asarray(rotation, dtype=float))
    tf.set_translation(np.asarray(translation, dtype=float))
    return tf


def _inertia(mass_kg: float, com_m, diag_kgm2) -> dart.dynamics.Inertia:
    return dart.dynamics.Inertia(mass_kg, np.asarray(com_m, dtype=float), np.diag(np.asarray(diag_kgm2, dtype=float)))


def _rot_x(angle_rad: float) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _add_collision_shape(body, shape, rel_tf, mu: float, name: str):
    node = body.createShapeNode(shape, name)
    node.setRelativeTransform(rel_tf)
    node.createVisualAspect()
    node.createCollisionAspect()
    node.createDynamicsAspect().setFrictionCoeff(float(mu))
    return node


def build_car_skeleton(car: CarDescription, name: str = "car",
                       wheel_shape: WheelShape = WheelShape.SPHERE) -> CarBody:
    """Build the multibody described in the module docstring; positions all zero."""
    ch, wh = car.chassis, car.wheels
    r, w_t, m_w = wh.radius_m, wh.width_m, wh.mass_kg
    m_k = KNUCKLE_MASS_FRACTION * m_w
    m_chassis = ch.mass_kg - 4.0 * m_w - 2.0 * m_k
    if m_chassis < 0.2 * ch.mass_kg:
        raise CarDescriptionError(
            f"{car.name}: chassis.mass_kg = {ch.mass_kg} is too small for four wheels of "
            f"wheels.mass_kg = {m_w}: expected the wheels to be under ~75 % of the total")

    skel = dart.dynamics.Skeleton(name)
    free_joint, chassis = skel.createFreeJointAndBodyNodePair()
    free_joint.setName("chassis_free")
    chassis.setName("chassis")
    box_c = np.array([0.5 * ch.length_m - ch.rear_overhang_m, 0.0, ch.cog_height_m])
    lx, ly, lz = ch.length_m, ch.width_m, ch.height_m
    box_moments = [m_chassis * (ly * ly + lz * lz) / 12.0, m_chassis * (lx * lx + lz * lz) / 12.0,
                   m_chassis * (lx * lx + ly * ly) / 12.0]
    if car.effects.inertia_scale != 1.0:  # the ``inertia`` effect (simrunner.car.effects)
        box_moments = [car.effects.inertia_scale * i for i in box_moments]
    chassis.setInertia(_inertia(m_chassis, box_c, box_moments))
    _add_collision_shape(chassis, dart.dynamics.BoxShape(np.array([lx, ly, lz])), isometry(box_c),
                         CHASSIS_MU, "chassis_box")

    i_spin = 0.5 * m_w * r * r
    i_across = m_w * (3.0 * r * r + w_t * w_t) / 12.0
    wheel_inertia = _inertia(m_w, [0.0, 0.0, 0.0], [i_across, i_spin, i_across])
    i_k = 0.4 * m_k * (0.5 * r) ** 2
    knuckle_inertia = _inertia(m_k, [0.0, 0.0, 0.0], [i_k, i_k, i_k])
    cylinder_tf = isometry(rotation=_rot_x(-0.5 * np.pi))  # cylinder z axis -> body y axis (axle)

    def revolute(parent, joint_name, body_name, offset, axis):
        props = dart.dynamics.RevoluteJointProperties()
        props.mName = joint_name
        props.mT_ParentBodyToJoint = isometry(offset)
        props.mAxis = np.asarray(axis, dtype=float)
        joint, body = skel.createRevoluteJointAndBodyNodePair(parent, props)
        body.setName(body_name)
        return joint, body

    def wheel(parent, tag, offset):
        joint, body = revolute(parent, f"{tag}_axle", tag, offset, [0.0, 1.0, 0.0])
        body.setInertia(wheel_inertia)
        if wheel_shape is WheelShape.CYLINDER:
            _add_collision_shape(body, dart.dynamics.CylinderShape(r, w_t), cylinder_tf,
                                 wh.friction_mu, f"{tag}_tyre")
        else:
            _add_collision_shape(body, dart.dynamics.SphereShape(r), isometry(), wh.friction_mu, f"{tag}_tyre")
        return joint, body

    half_t, wb = 0.5 * ch.track_m, ch.wheelbase_m
    knuckles, front = [], []
    for side, y in (("l", half_t), ("r", -half_t)):
        kj, kb = revolute(chassis, f"knuckle_{side}_steer", f"knuckle_{side}", [wb, y, r], [0.0, 0.0, 1.0])
        kb.setInertia(knuckle_inertia)
        knuckles.append(kj)
        front.append(wheel(kb, f"wheel_f{side}", [0.0, 0.0, 0.0]))
    rear = [wheel(chassis, "wheel_rl", [0.0, half_t, r]), wheel(chassis, "wheel_rr", [0.0, -half_t, r])]
    wheels = front + rear
    return CarBody(skeleton=skel, chassis=chassis, free_joint=free_joint,
                   knuckle_joints=tuple(knuckles), wheel_joints=tuple(j for j, _ in wheels),
                   wheel_bodies=tuple(b for _, b in wheels), wheel_spin_inertia_kgm2=i_spin,
                   total_mass_kg=ch.mass_kg)
