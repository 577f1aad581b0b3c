"""The simulation loop: joint torques past the actuators' limits (the feet-balance path), every kind of help
it counts, and the hand-overs to another controller in place of a reset or of a take-off that falls short
(``simulate``'s ``recover`` and ``flights``)."""

from __future__ import annotations

import numpy as np

from physmotion.physics.humanoid import build_model, foot_lift
from physmotion.physics.retarget import joints_to_qpos
from physmotion.physics.sim import simulate
from physmotion.physics.tracking import ModelBasedTracker, TrackingConfig, prepare_reference
from physmotion.skeleton import REST_OFFSETS, rest_joints


class _Pushing(ModelBasedTracker):
    """The tracker plus a joint torque applied directly on the left knee, at ``extra`` x its limit."""

    def __init__(self, model, extra: float) -> None:
        super().__init__(model, TrackingConfig(feet_balance=False))
        self.extra = extra

    def residual(self, data, ref, step, substeps):
        out = super().residual(data, ref, step, substeps)
        knee = 6 + 9  # any hinge: actuator i drives dof 6 + i
        out[knee] = self.extra * self.model.actuator_forcerange[knee - 6, 1]
        return out


def test_over_limit_flags_direct_joint_torques() -> None:
    model = build_model(REST_OFFSETS)
    standing = np.repeat(rest_joints(REST_OFFSETS)[None], 20, axis=0)
    qpos = joints_to_qpos(standing, model, lift=foot_lift(REST_OFFSETS))
    ref = prepare_reference(model, qpos, 1 / 30)
    quiet = simulate(model, ref, ModelBasedTracker(model, TrackingConfig(feet_balance=False)))
    assert quiet.over_limit.shape == (20,) and not quiet.over_limit.any()
    pushed = simulate(model, ref, _Pushing(model, 2.5), fail_mpjpe=10.0)
    assert pushed.over_limit[1:].mean() > 0.5  # 2.5x the limit: more than the actuator can oppose
    small = simulate(model, ref, _Pushing(model, 0.01), fail_mpjpe=10.0)
    assert not small.over_limit.any()


def test_help_in_full_counts_every_cap_and_keeps_the_peaks(real_walk: np.ndarray) -> None:
    """A real walk tracked under tight caps: frames held at the force cap, at the lift cap alone or at the
    torque cap alone are all counted (the mean-force rule saw only the first); the per-step peak is never
    under the step's mean and is above it where the residual varies within the step."""
    from physmotion.physics.projection import ProjectionConfig, prepare_motion

    prep = prepare_motion(real_walk[:60], 20.0, ProjectionConfig())
    ref = prepare_reference(prep.model, prep.target, 1 / 30)

    def run(**caps) -> object:
        tracking = TrackingConfig(feet_balance=False, **caps)
        return simulate(prep.model, ref, ModelBasedTracker(prep.model, tracking), fail_mpjpe=10.0)

    loose = run(residual_force=10.0, residual_lift=10.0, residual_torque=10.0)
    assert not loose.at_cap.any()
    assert np.all(loose.residual_force_peak >= loose.residual_force - 1e-12)
    assert np.mean(loose.residual_force_peak > 1.01 * loose.residual_force) > 0.5
    force = run(residual_force=0.01, residual_lift=10.0, residual_torque=10.0)
    lift = run(residual_force=10.0, residual_lift=0.005, residual_torque=10.0)
    torque = run(residual_force=10.0, residual_lift=10.0, residual_torque=0.005)
    for roll in (force, lift, torque):
        assert roll.at_cap[1:].mean() > 0.3, roll.at_cap.mean()
    # the lift cap binds while the force's norm is far from its own: the old mean-force rule missed it
    assert np.all(lift.residual_force[lift.at_cap] < 0.99 * 10.0)


def test_a_body_handed_back_off_the_motion_goes_on_with_the_recovery() -> None:
    """``simulate``'s ``recover``: a stretch another controller carried to the last step stands whatever its
    error there (that controller judges falls, not the distance to the motion); one that ends earlier with
    the body still off the motion is handed to it again from there, and only where it gives up is the
    body reset."""
    from physmotion.physics.sim import Recovery

    model = build_model(REST_OFFSETS)
    standing = np.repeat(rest_joints(REST_OFFSETS)[None], 20, axis=0)
    standing[10:, :, 0] += 0.5  # the motion steps 0.5 m sideways in one frame: the tracker is left behind
    ref = prepare_reference(model, joints_to_qpos(standing, model, lift=foot_lift(REST_OFFSETS)), 1 / 30)
    tracker = ModelBasedTracker(model, TrackingConfig(feet_balance=False))

    def carry_until(stop: int, calls: list):
        def recover(ref, states, k, earliest, accept):  # hold step 5's state (0.5 m off) until stop
            calls.append((k, earliest))
            if len(calls) > 1:
                return None  # handed back again: gives up
            m = stop - 5 + 1
            return Recovery(5, np.repeat(states[5:6, : model.nq], m, axis=0), np.zeros((m, model.nv)),
                            np.full(m, 0.5), np.zeros((m, 4), dtype=bool))  # fmt: skip

        return recover

    calls: list = []
    to_end = simulate(model, ref, tracker, fail_mpjpe=0.15, reset_on_fail=True, recover=carry_until(19, calls))
    assert calls == [(10, 0)] and to_end.recovered == 1 and to_end.resets == 0 and to_end.recovered_steps[6:].all()
    calls = []
    short = simulate(model, ref, tracker, fail_mpjpe=0.15, reset_on_fail=True, recover=carry_until(15, calls))
    assert calls == [(10, 0), (15, 15)] and short.recovered == 1 and short.resets == 1 and short.reset_steps[15]


def test_a_flight_the_body_falls_short_of_is_handed_over_and_kept_only_where_it_flies_higher() -> None:
    """``simulate``'s ``flights``: at a flight's check step, a body that has cleared the floor by less than
    ``flight_kept`` x the reference's flight is handed to ``recover`` with a test of the stretch it returns;
    a stretch in which the body flies higher is kept (no outside hand on it), one that does not leaves the
    tracker's rollout as it was; a body that flies high enough is not handed over."""
    from physmotion.physics.sim import FlightCheck, Recovery

    model = build_model(REST_OFFSETS)
    standing = np.repeat(rest_joints(REST_OFFSETS)[None], 20, axis=0)
    ref = prepare_reference(model, joints_to_qpos(standing, model, lift=foot_lift(REST_OFFSETS)), 1 / 30)
    tracker = ModelBasedTracker(model, TrackingConfig(feet_balance=False))
    plain = simulate(model, ref, tracker, fail_mpjpe=10.0, reset_on_fail=True)

    def lifted_by(dz: float, calls: list):
        def recover(ref, states, k, earliest, accept):  # steps 5..k again, the body dz higher
            calls.append(k)
            qpos = states[5 : k + 1, : model.nq].copy()
            qpos[:, 2] += dz
            m = len(qpos)
            got = Recovery(5, qpos, states[5 : k + 1, model.nq :], np.zeros(m), np.zeros((m, 4), dtype=bool))
            return got if accept(got) else None

        return recover

    flight = [FlightCheck(takeoff=5, check=10, height=0.2)]  # a 20 cm flight the standing body never makes
    calls: list = []
    higher = simulate(model, ref, tracker, fail_mpjpe=10.0, reset_on_fail=True, recover=lifted_by(0.3, calls),
                      flights=flight, flight_kept=0.8)  # fmt: skip
    assert calls == [10] and higher.recovered == 1 and higher.resets == 0
    np.testing.assert_allclose(higher.qpos[5:11, 2], plain.qpos[5:11, 2] + 0.3)
    assert higher.recovered_steps[6:11].all() and not higher.recovered_steps[11:].any()
    assert not higher.residual_force[6:11].any() and higher.residual_force[12:].all()
    calls = []
    level = simulate(model, ref, tracker, fail_mpjpe=10.0, reset_on_fail=True, recover=lifted_by(0.0, calls),
                     flights=flight, flight_kept=0.8)  # fmt: skip
    assert calls == [10] and level.recovered == 0
    np.testing.assert_array_equal(level.qpos, plain.qpos)
    calls = []
    low = [FlightCheck(takeoff=5, check=10, height=-1.0)]  # a "flight" 1 m under the floor: cleared
    kept = simulate(model, ref, tracker, fail_mpjpe=10.0, reset_on_fail=True, recover=lifted_by(0.3, calls),
                    flights=low, flight_kept=0.8)  # fmt: skip
    assert calls == [] and kept.recovered == 0
