"""Small structures for analytic checks, built from the same spec types as the robots."""

from __future__ import annotations

import numpy as np

from spinefarm.robot.bodies import build_bodies, build_strings
from spinefarm.robot.engines import engine_names
from spinefarm.robot.morphology.structure import Rod, RodMaterial, String, StringMaterial, StructureSpec
from spinefarm.robot.scene import GroundSpec
from spinefarm.worker.engines.base import engine_class
from spinefarm.worker.sim import strings as sk

ENGINES = tuple(engine_names())


def two_rod_structure(gap_cm: float, *, heavy_density: float = 0.014, light_density: float = 0.014,
                      stiffness: float = 1000.0, damping: float = 0.0) -> StructureSpec:
    """Two rods on the x axis (high above the ground) joined end to end by one string across gap_cm."""
    y, length = 200.0, 10.0
    nodes = ((-length - gap_cm / 2, y, 0.0), (-gap_cm / 2, y, 0.0), (gap_cm / 2, y, 0.0),
             (gap_cm / 2 + length, y, 0.0))
    return StructureSpec(
        name="pair", nodes=nodes, node_segment=(0, 0, 1, 1),
        rods=(Rod(0, 1, "anchor"), Rod(2, 3, "mass")), strings=(String(1, 2, "spring"),),
        rod_materials=(("anchor", RodMaterial(density_kg_per_cm3=heavy_density)),
                       ("mass", RodMaterial(density_kg_per_cm3=light_density))),
        string_materials=(("spring", StringMaterial(stiffness_n_per_m=stiffness, damping_n_s_per_m=damping)),),
    )


def mass_between_anchors(gap_cm: float, *, anchor_density: float, stiffness: float = 1000.0) -> StructureSpec:
    """A light rod between two heavy rods on the x axis, tied to each by one string across gap_cm."""
    y, length = 200.0, 10.0
    x0 = -length / 2 - gap_cm
    xs = [x0 - length, x0, -length / 2, length / 2, length / 2 + gap_cm, length / 2 + gap_cm + length]
    return StructureSpec(
        name="triple", nodes=tuple((x, y, 0.0) for x in xs), node_segment=(0, 0, 1, 1, 2, 2),
        rods=(Rod(0, 1, "anchor"), Rod(2, 3, "mass"), Rod(4, 5, "anchor")),
        strings=(String(1, 2, "spring"), String(3, 4, "spring")),
        rod_materials=(("anchor", RodMaterial(density_kg_per_cm3=anchor_density)), ("mass", RodMaterial())),
        string_materials=(("spring", StringMaterial(stiffness_n_per_m=stiffness, damping_n_s_per_m=0.0)),),
    )


class PassiveRig:
    """A scene with fixed-rest-length strings, stepped with the production kernel and engine."""

    def __init__(self, spec: StructureSpec, rest_cm: np.ndarray | None = None, dt: float = 1e-4,
                 gravity: float = 0.0, engine: str = "bullet") -> None:
        self.bodies = build_bodies(spec)
        geom = build_strings(spec, self.bodies)
        n = len(spec.strings)
        params = np.zeros((n, sk.N_PARAM))
        state = np.zeros((n, sk.N_STATE))
        for i, s in enumerate(spec.strings):
            mat = spec.string_material(s.tag)
            params[i, sk.P_K] = mat.stiffness_n_per_m
            params[i, sk.P_B] = mat.damping_n_s_per_m
            params[i, sk.P_MODE] = sk.MODE_FIXED
            params[i, sk.P_NODE] = -1
        state[:, sk.S_REST] = geom.start_length_cm if rest_cm is None else rest_cm
        state[:, sk.S_LPREV] = geom.start_length_cm
        self.bank = sk.StringBank(len(self.bodies), geom.body_a, geom.body_b, geom.anchor_a_cm,
                                  geom.anchor_b_cm, params, state)
        cls = engine_class(engine)
        self.scene = cls(self.bodies, GroundSpec(), dt, cls.settings_from_options({"gravity_cm_s2": gravity}))
        self.dt = dt
        self.no_cpg = np.zeros(0)

    def step(self) -> np.ndarray:
        poses = self.scene.read_poses()[0]  # one world
        status = self.bank.step(poses, self.no_cpg, self.dt, sk.MOTOR_PHYSICAL)
        assert status == sk.STATUS_OK
        self.scene.apply_wrenches(self.bank.force[None], self.bank.torque[None])
        self.scene.step()
        return poses

    def close(self) -> None:
        self.scene.close()
