import json

import numpy as np
import pytest

from paretocal.camera import Camera
from paretocal.decide import Decision, choose, decide, knee_index, reprojection_deviation
from paretocal.errors import SettingsError
from paretocal.search.basin import BasinTest
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
        assert i == 1 and d.solutions_within_budget == 2 and d.budget_ms == 0.6

    def test_budget_too_small(self):
        with pytest.raises(SettingsError, match="cheapest needs 0.1 ms"):
            choose(self.F, self.ms, "budget", 0.01)

    def test_min_chamfer(self):
        assert choose(self.F, self.ms, "min-chamfer")[0] == 2


#: A basin test of a KITTI demo run as result.json writes it (decision.basin).
TWO_BASINS = {"separation_px": 45.743, "separation_deg": 3.6163, "separation_cm": 11.749,
              "departure_near": 0.428, "departure_far": 0.299, "ambiguous": False,
              "same_basin": False, "mean_px": 1.4247, "se_px": 0.0572, "t": 24.8903, "p": 0.0,
              "frames": 20, "frames_far_better": 20, "kept": "far",
              "alternative": [0.12826093356461135, 0.03364998527284297, 0.003493531482666901,
                              -0.25987171168437895, -0.027153938121025473, -0.4451678801692799],
              "rebuilt": False}
ONE_BASIN = {"separation_px": 0.41, "separation_deg": 0.0123, "separation_cm": 0.9,
             "departure_near": 0.01, "departure_far": 0.02, "ambiguous": False,
             "same_basin": True, "kept": "far"}


def test_the_basin_test_is_held_in_metres_and_written_as_it_was():
    two = BasinTest.from_dict(TWO_BASINS)
    assert two.separation_m == pytest.approx(0.11749) and two.alternative.shape == (6,)
    assert two.frames == 20 and two.kept == "far" and not two.same_basin
    assert json.dumps(two.to_dict()) == json.dumps(TWO_BASINS)
    one = BasinTest.from_dict(ONE_BASIN)           # 0.9 cm: not 0.9 again by / 100 * 100
    assert one.frames is None and one.alternative is None and one.rebuilt is None
    assert json.dumps(one.to_dict()) == json.dumps(ONE_BASIN)


class TestDecisionRecord:
    F = np.array([[3.0, 0.0], [1.0, 0.5], [0.8, 2.0]])
    ms = np.array([0.1, 0.5, 2.0])
    dev = np.array([4.0, 0.5, 0.0])

    def test_knee(self):
        """The knee rule's decision, then what the run adds, in result.json's order."""
        i, d = decide(self.F, self.ms, self.dev, "knee", max_deviation_px=1.0)
        assert (d.rule, d.deviation_px, d.max_deviation_px) == ("knee", self.dev[i], 1.0)
        assert d.n_points is None and d.measured_ms is None
        assert list(d.to_dict()) == ["rule", "method", "deviation_px", "figure",
                                     "max_deviation_px"]
        basin = BasinTest.from_dict(TWO_BASINS)
        run = d.with_run(n_points=46, front_size=3, polished=True, best_supported_n=120,
                         basin=basin, measured_ms=0.0075)
        doc = run.to_dict()
        assert list(doc) == ["rule", "method", "deviation_px", "figure", "max_deviation_px",
                             "n_points", "front_size", "polished", "best_supported_n", "basin",
                             "measured_ms"]
        assert doc["n_points"] == 46 and doc["basin"] == TWO_BASINS
        assert doc["measured_ms"] == 0.0075
        assert Decision.from_dict(doc).to_dict() == doc
        assert json.dumps(doc) == json.dumps(Decision.from_dict(json.loads(json.dumps(doc)))
                                             .to_dict())

    def test_budget_and_min_chamfer(self):
        i, d = decide(self.F, self.ms, self.dev, "budget", budget_ms=0.6)
        doc = d.with_run(n_points=10, front_size=3, polished=False, best_supported_n=40,
                         basin=None, measured_ms=0.5).to_dict()
        assert list(doc)[:4] == ["rule", "budget_ms", "solutions_within_budget", "deviation_px"]
        assert doc["basin"] is None and "max_deviation_px" not in doc
        assert Decision.from_dict(doc).to_dict() == doc
        i, d = decide(self.F, self.ms, self.dev, "min-chamfer")
        assert i == 2 and d.to_dict() == {"rule": "min-chamfer", "deviation_px": 0.0}


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
