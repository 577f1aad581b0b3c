"""The simulation loop's report of joint torques past the actuators' limits (the feet-balance path)."""

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
