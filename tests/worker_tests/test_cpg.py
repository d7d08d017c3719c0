"""CPG: phase locking, amplitude dynamics, integrator accuracy."""

from __future__ import annotations

import math

import numpy as np

from spinefarm.worker.control.cpg import SLOW_RATE_STEP, CpgIntegrator, CpgNetwork


def pair(psi: float, weight: float = 2.0, omega: float = 2 * math.pi, amp: float = 10.0) -> CpgNetwork:
    # locks phi_1 = phi_0 + psi: node m taking psi_mt from t settles at phi_m = phi_t - psi_mt
    return CpgNetwork(node_string=np.array([0, 1]), omega_rad_s=np.array([omega, omega]),
                      amplitude_cm_s=np.array([amp, amp]), indptr=np.array([0, 1, 2]),
                      source=np.array([1, 0]), weight=np.array([weight, weight]), phase_rad=np.array([psi, -psi]))


def test_two_coupled_oscillators_lock_to_the_prescribed_phase():
    for psi in (0.7, -2.0, 2.5):
        cpg = CpgIntegrator(pair(psi))
        cpg.state[1, 0] = 1.3  # start out of phase
        for _ in range(3000):
            cpg.advance(1e-3)
        diff = (cpg.state[1, 0] - cpg.state[0, 0] - psi + math.pi) % (2 * math.pi) - math.pi
        assert abs(diff) < 1e-6


def test_amplitude_is_critically_damped_with_time_constant_2_over_a():
    a, amp = 20.0, 10.0
    cpg = CpgIntegrator(pair(0.0, amp=amp))
    for step in range(1, 1001):
        cpg.advance(1e-3)
        t = step * 1e-3
        expected = amp - amp * (1 + a * t / 2) * math.exp(-a * t / 2)
        assert abs(cpg.state[0, 1] - expected) < 1e-6 * amp
    assert abs(cpg.state[0, 1] - amp) < 1e-3 * amp


def test_rk4_at_physics_rate_agrees_with_a_fine_reference():
    rng = np.random.default_rng(1)
    n = 12
    src = np.array([j for i in range(n) for j in range(n) if j != i])
    indptr = np.arange(0, n * (n - 1) + 1, n - 1)
    net = CpgNetwork(np.arange(n), np.full(n, 2 * math.pi * 3.0), np.full(n, 60.0), indptr, src,
                     rng.random(len(src)), rng.uniform(-math.pi, math.pi, len(src)))
    coarse, fine = CpgIntegrator(net, 1e-3), CpgIntegrator(net, 1e-3 / 16)
    for _ in range(2000):
        coarse.advance(1e-3)
        fine.advance(1e-3)
    assert np.max(np.abs(coarse.output_cm_s - fine.output_cm_s)) < 1e-3 * 60.0


def test_fastest_rate_counts_frequency_coupling_gain_and_amplitude_rate():
    net = pair(0.3, weight=2.0, omega=2 * math.pi, amp=10.0)
    assert math.isclose(net.fastest_rate_per_s(), 2 * math.pi + 2.0 * 10.0)
    assert net.fastest_rate_per_s() > net.amplitude_rate_per_s
    still = pair(0.0, weight=0.0, omega=1.0)
    assert still.fastest_rate_per_s() == still.amplitude_rate_per_s


def test_default_sub_step_lengthens_only_for_slow_networks_and_an_explicit_cap_holds():
    slow, fast = pair(0.5), pair(0.5, omega=2 * math.pi * 60.0)
    assert CpgIntegrator(slow).plan(2e-3) == (2e-3, 1)  # 0.25 / 26.3 per s allows 9.5 ms
    assert CpgIntegrator(slow).plan(1e-3) == (1e-3, 1)
    assert CpgIntegrator(fast).plan(2e-3) == (1e-3, 2)  # 60 Hz: the 1 ms sub-step
    assert CpgIntegrator(slow, 1e-3).plan(2e-3) == (1e-3, 2)
    assert CpgIntegrator(slow).plan(0.1)[1] == math.ceil(0.1 / (SLOW_RATE_STEP / slow.fastest_rate_per_s()))


def test_one_long_step_on_a_slow_network_agrees_with_a_fine_reference():
    net = pair(0.8, weight=2.0, amp=40.0)  # rate 86 per s: one 2 ms step is 0.17 of it
    long, fine = CpgIntegrator(net), CpgIntegrator(net, 1e-3 / 16)
    long.state[1, 0] = fine.state[1, 0] = 1.3
    assert long.plan(2e-3)[1] == 1
    for _ in range(5000):  # 10 s of 2 ms updates
        long.advance(2e-3)
        fine.advance(2e-3)
    assert np.max(np.abs(long.output_cm_s - fine.output_cm_s)) < 1e-6 * 40.0
