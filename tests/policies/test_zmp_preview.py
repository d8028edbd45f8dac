"""ZMP preview control (issue #14's teacher core): the pendulum's ZMP follows a stepping
reference, and the CoM moves before the reference does."""

import numpy as np
import pytest

from legcal_bench.policies.zmp_preview import preview_gains, track


def test_the_zmp_follows_a_stepping_reference_and_the_com_anticipates():
    dt, z_c = 0.01, 0.8
    g = preview_gains(z_c, dt)
    # Lateral ZMP: 1 s centred, then alternate feet +-0.1 m every 0.5 s, then centred.
    t = np.arange(0, 6, dt)
    ref = np.where(t < 1, 0.0, np.where((t - 1) // 0.5 % 2 == 0, 0.1, -0.1))
    ref[t >= 5] = 0.0
    X, P = track(g, ref)
    settled = (t > 1.6) & (t < 5)
    # Away from the switches the model's ZMP sits on the reference foot ...
    switch = np.abs(np.diff(ref, prepend=ref[0])) > 0
    near = np.convolve(switch, np.ones(15), mode="same") > 0
    assert np.abs(P - ref)[settled & ~near].max() < 0.01
    # ... the CoM sways less than the feet are apart, and starts before the first step.
    assert np.abs(X[settled, 0]).max() < 0.1
    assert abs(X[int(0.9 / dt), 0]) > 1e-3
    # And it comes back to rest in the middle.
    assert abs(X[-1, 0]) < 0.005 and abs(X[-1, 1]) < 0.01


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError):
        preview_gains(-0.8, 0.01)
    with pytest.raises(ValueError):
        preview_gains(0.8, 0.01, preview_s=0.001)
