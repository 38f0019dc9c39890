import numpy as np
import pytest

from paretocal.camera import Camera
from paretocal.decide import choose, knee_index, reprojection_deviation
from paretocal.errors import SettingsError
from paretocal.geometry import correction_matrix


class TestKnee:
    def test_convex_front(self):
        n = np.linspace(1, 100, 100)
        F = np.column_stack([1.0 / n, n])
        i = knee_index(F)
        # For y = 1/x normalised over [1, 100], the farthest point below the chord is near
        # x = sqrt(100) = 10.
        assert 7 <= n[i] <= 13

    def test_corner(self):
        F = np.array([[10.0, 0.0], [1.0, 1.0], [0.9, 10.0]])
        assert knee_index(F) == 1

    def test_straight_line_has_no_knee(self):
        F = np.column_stack([np.linspace(1, 0, 5), np.linspace(0, 1, 5)])
        assert knee_index(F) == int(np.argmin(F[:, 0]))

    def test_tiny_fronts(self):
        assert knee_index(np.array([[1.0, 2.0]])) == 0
        assert knee_index(np.array([[1.0, 2.0], [0.5, 3.0]])) == 1


class TestChoose:
    F = np.array([[3.0, 0.0], [1.0, 0.5], [0.8, 2.0]])
    ms = np.array([0.1, 0.5, 2.0])

    def test_budget(self):
        i, d = choose(self.F, self.ms, "budget", 0.6)
        assert i == 1 and d["solutions_within_budget"] == 2

    def test_budget_too_small(self):
        with pytest.raises(SettingsError, match="cheapest needs 0.1 ms"):
            choose(self.F, self.ms, "budget", 0.01)

    def test_min_chamfer(self):
        assert choose(self.F, self.ms, "min-chamfer")[0] == 2


class TestDeviation:
    def test_zero_for_same_pose_and_grows_with_rotation(self, rng):
        cam = Camera(K=np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]), width=640,
                     height=480)
        pts = np.column_stack([rng.uniform(-5, 5, 500), rng.uniform(-3, 3, 500),
                               rng.uniform(8, 30, 500)])
        T0 = np.eye(4)
        T = np.stack([T0 @ correction_matrix([0, 0, 0, 0, a, 0]) for a in (0.0, 0.1, 0.5)])
        d = reprojection_deviation(T, T0, [pts], [cam])
        assert d[0] == pytest.approx(0.0, abs=1e-9)
        # With an identity extrinsic the "pitch" correction turns about the camera's y axis:
        # 0.1 deg moves points sideways by about f * 0.1 deg = 0.87 px at f = 500 px.
        assert 0.5 < d[1] < 1.2 and d[2] == pytest.approx(5 * d[1], rel=0.05)
