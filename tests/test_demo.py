"""The demo's keyframed performance."""
import numpy as np

from data_synth.facs import FACS_INDEX
from retarget.commands.demo import PERFORMANCE, performance


def test_performance_hits_its_keyframes_and_stays_in_range():
    w = performance(91)  # 30 fps over 3 s: keyframe k at frame 30 * t_k exactly
    assert w.shape == (91, 53) and w.min() >= 0 and w.max() <= 1
    for t, pose in PERFORMANCE:
        frame = int(round(t * 30))
        expected = np.zeros(53, np.float32)
        for name, value in pose.items():
            expected[FACS_INDEX[name]] = value
        assert np.allclose(w[frame], expected), t
    assert np.abs(np.diff(w, axis=0)).max() < 0.1  # smooth: no jumps between frames
    assert performance(1).shape == (1, 53)
