"""The paper's studies: their numerical parts on exact toy problems, and the whole study on
real frames (tiny budgets)."""

from __future__ import annotations

import csv
import json
import re

import numpy as np
import pytest

from paretocal.cli import main
from paretocal.decide import chord_distance, knee_region
from paretocal.apps.study import StudyPlan, run_study
from paretocal.apps.study.epsilon import epsilon_constraint, front_f1_at
from paretocal.apps.study.innovization import correlations, findings, trends
from paretocal.apps.study.robustness import summarise_sweep
from paretocal.apps.study.single import single_objective

TARGET = np.array([0.1, -0.2, 0.05, 1.5, -2.0, 0.5])
XL = np.array([-1.5, -1.5, -1.5, -25, -25, -25, 10])
XU = np.array([1.5, 1.5, 1.5, 25, 25, 25, 1000])


def toy_chamfer(X):
    """A bowl around TARGET plus a 1/sqrt(n) sampling term: f1's minimum at n is 1/sqrt(n)."""
    X = np.atleast_2d(X)
    scale = np.array([0.1, 0.1, 0.1, 1.0, 1.0, 1.0])
    return np.sum(((X[:, :6] - TARGET) / scale) ** 2, axis=1) + 1.0 / np.sqrt(X[:, 6])


class ToyObjective:
    """f1 = toy_chamfer, f2 = (n - 10) / 990 (cost linear in n, like the real one)."""

    def chamfer(self, X):
        return {"f1": toy_chamfer(X)}

    def evaluate(self, X):
        X = np.atleast_2d(X)
        return np.column_stack([toy_chamfer(X), (np.rint(X[:, 6]) - 10) / 990])


class TestSingleObjective:
    def test_de_and_powell_find_the_bowl_minimum(self):
        r = single_objective(toy_chamfer, 400, XL, XU, pop=40, gens=40, seed=1)
        assert r["x"][6] == 400
        assert np.all(np.abs(r["x"][:6] - TARGET) < [2e-3] * 3 + [2e-2] * 3)
        assert r["f1"] <= r["f1_de"]
        assert r["f1"] == pytest.approx(1 / np.sqrt(400), abs=1e-3)
        best = [h["best_f1"] for h in r["de_history"]]
        assert len(best) == 40 and all(b2 <= b1 for b1, b2 in zip(best, best[1:]))
        assert r["local_history"] and r["evaluations"] > 40 * 40

    def test_deterministic(self):
        a = single_objective(toy_chamfer, 100, XL, XU, pop=20, gens=5, seed=3, local_maxfev=50)
        b = single_objective(toy_chamfer, 100, XL, XU, pop=20, gens=5, seed=3, local_maxfev=50)
        np.testing.assert_array_equal(a["x"], b["x"])


class TestEpsilonConstraint:
    def test_front_lookup(self):
        F = np.array([[3.0, 0.0], [2.0, 0.5], [1.0, 1.0]])
        assert front_f1_at(F, 0.6) == 2.0
        assert front_f1_at(F, 1.0) == 1.0
        assert front_f1_at(F, -0.1) == np.inf

    def test_points_respect_the_limit_and_meet_the_exact_front(self):
        # The exact front: pose at TARGET, f1 = 1/sqrt(n), f2 = (n - 10)/990.
        n = np.arange(10, 1001)
        F_exact = np.column_stack([1 / np.sqrt(n), (n - 10) / 990])
        rows = epsilon_constraint(ToyObjective(), [0.05, 0.3, 1.0], XL, XU, pop=60, gens=40,
                                  seed=0, F_front=F_exact, polish_iters=10)
        for r in rows:
            assert r["feasible"] and r["f2"] <= r["eps"] + 1e-12
            assert r["f1"] <= r["f1_ga"] + 1e-12
            # Within 2 % of the exact front's value at the same limit.
            assert r["gap"] == pytest.approx(0.0, abs=0.02 * r["front_f1"])


class TestInnovization:
    def test_trends_recover_the_generating_laws(self, rng):
        n = np.geomspace(20, 2000, 30).round()
        X = np.zeros((30, 7))
        X[:, 6] = n
        X[:, 0] = 0.05 + 0.01 * np.log(n)      # x drifts with n
        X[:, 3] = 1.25                          # yaw shared by all
        X[:, 4] = rng.normal(0, 0.3, 30)        # pitch: noise
        F = np.column_stack([-2.0 + 8.0 / np.sqrt(n), 0.001 * n - 0.02])
        fits = trends(X, F)
        assert fits["cost_vs_n"]["b"] == pytest.approx(0.001)
        assert fits["cost_vs_n"]["r2"] == pytest.approx(1.0)
        assert fits["chamfer_vs_n"]["a"] == pytest.approx(-2.0)
        assert fits["chamfer_vs_n"]["b"] == pytest.approx(8.0)
        assert fits["variable_vs_n"]["x"]["b"] == pytest.approx(0.01)
        corr = correlations(X, F)
        rho = {(r["variable"], r["objective"]): r["spearman"] for r in corr}
        assert rho[("n", "f1")] == pytest.approx(-1.0) and rho[("n", "f2")] == pytest.approx(1.0)
        assert np.isnan(rho[("yaw", "f1")])          # constant: no correlation defined
        text = " ".join(findings(X, F, np.r_[XU[:6], 495]))
        assert "yaw = +1.25 deg" in text               # shared
        assert re.search(r"x \(rho = \+1\.00", text)    # moving with n
        assert "pitch (rho" not in text                 # noise is not a trend
        assert "falls with n" in text


class TestRobustnessSummary:
    def test_best_weight_by_reference_error_and_by_spread(self):
        T = np.eye(4)
        T2 = np.eye(4)
        T2[0, 3] = 0.5
        rows = [{"w1": 0.1, "f1": -1.0, "T": T, "rotation_deg": 5.0, "translation_cm": 40.0},
                {"w1": 0.1, "f1": -1.1, "T": T2, "rotation_deg": 6.0, "translation_cm": 60.0},
                {"w1": 0.8, "f1": -2.0, "T": T, "rotation_deg": 0.2, "translation_cm": 2.0},
                {"w1": 0.8, "f1": -2.1, "T": T, "rotation_deg": 0.3, "translation_cm": 3.0}]
        s = summarise_sweep(rows)
        assert s["best_w1"] == 0.8 and "reference" in s["basis"]
        per = {p["w1"]: p for p in s["per_weight"]}
        assert per[0.1]["seed_spread"] == pytest.approx(5.0)   # 50 cm / 10
        assert per[0.8]["seed_spread"] == 0.0
        blind = [{k: v for k, v in r.items() if k not in ("rotation_deg", "translation_cm")}
                 for r in rows]
        s = summarise_sweep(blind)
        assert s["best_w1"] == 0.8 and "spread" in s["basis"]


def test_knee_region_surrounds_the_knee():
    # Normalised distances below the chord x + y = 1: 0.789, 0.644, 0.378 (times 1/sqrt 2).
    F = np.array([[1.0, 0.0], [0.2, 0.1], [0.15, 0.3], [0.12, 0.6], [0.1, 1.0]])
    d = chord_distance(F)
    assert np.argmax(d) == 1 and d[0] == pytest.approx(0) and d[-1] == pytest.approx(0)
    assert d[1] == pytest.approx((1 - 0.1 / 0.9 - 0.1) / np.sqrt(2))
    assert list(knee_region(F, 0.5)) == [1, 2]


TINY = StudyPlan(pop=24, gens=4, frame_stride=1, eps_count=2, eps_pop=12, eps_gens=3,
                 weights=(0.5, 0.9), robust_seeds=(0,), robust_pop=12, robust_gens=2,
                 robust_frame_stride=1)
FILES = ("pareto_front", "solution_space", "single_objective", "epsilon_constraint", "decision",
         "innovization", "robustness")


@pytest.fixture(scope="module")
def study(tmp_path_factory, raw_frames):
    from paretocal.config import Settings
    from paretocal.geometry import correction_matrix

    out = tmp_path_factory.mktemp("study")
    T_init = raw_frames[0].T_ref @ correction_matrix(np.array([0.05, -0.03, 0.02, 1, -1, 0.5]))
    settings = Settings().replace(decision={"polish_iters": 2})
    doc = run_study(raw_frames[:2], out, T_init, settings, TINY)
    return out, doc


class TestStudyOnRealFrames:
    def test_every_study_writes_its_csv_and_png(self, study):
        out, doc = study
        for name in FILES:
            assert (out / f"{name}.png").stat().st_size > 10_000, name
            with open(out / f"{name}.csv") as fh:
                rows = list(csv.DictReader(fh))
            assert rows, name
        assert (out / "projections.png").exists() and (out / "calibration" / "result.json").exists()
        assert not list(out.glob("*.tmp*"))

    def test_tables_hold_what_they_claim(self, study):
        out, doc = study
        with open(out / "pareto_front.csv") as fh:
            front = list(csv.DictReader(fh))
        assert sum(int(r["chosen"]) for r in front) == 1
        assert "ref_rotation_deg" in front[0]
        with open(out / "robustness.csv") as fh:
            rob = list(csv.DictReader(fh))
        assert sorted({float(r["w1"]) for r in rob}) == [0.5, 0.9]
        assert all(float(r["w1"]) + float(r["w2"]) == pytest.approx(1) for r in rob)
        for r in doc["epsilon_constraint"]:
            if r["feasible"]:
                assert r["f2"] <= r["eps"] + 1e-12
        assert doc["robustness"]["best_w1"] in (0.5, 0.9)
        assert doc["innovization"]["findings"][0].startswith("The set holds")
        assert doc["single_objective"]["f1"] <= doc["single_objective"]["f1_de"]
        json.loads((out / "study.json").read_text())

    def test_report_is_self_contained(self, study):
        out, doc = study
        page = (out / "report.html").read_text()
        assert page.count("data:image/png;base64,") == 8
        assert not re.search(r"(src|href)=[\"']https?://", page)
        for text in ("Pareto front", "Innovization", "Robustness", "Epsilon-constraint",
                     doc["libraries"]["pymoo"]):
            assert text in page


def test_cli_study_quick_bad_input(tmp_path, capsys):
    code = main(["study", str(tmp_path / "missing"), "--out", str(tmp_path / "o"), "--quick"])
    assert code == 2
    assert "missing" in capsys.readouterr().err
