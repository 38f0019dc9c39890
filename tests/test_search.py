import numpy as np
import pytest

from paretocal.config import SearchSettings
from paretocal.search import front_of, run_nsga2
from paretocal.search.polish import fd_gradient_hessian, newton_polish, polish
from paretocal.search.seeding import grid_seeds, rotation_grid

from .helpers import load_benchmark


def _quadratic(center, H):
    """A convex quadratic in the six pose variables with correlated axes (a diagonal valley)."""
    def f(X):
        d = X[:, :6] - center
        return np.einsum("ki,ij,kj->k", d, H, d)
    return f


@pytest.fixture
def valley(rng):
    # Correlated axes and a condition number of 200 in units of the difference steps (1 cm,
    # 0.1 deg): the regime the polish is designed for.
    from paretocal.search.polish import DEFAULT_FD_STEP

    Q, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    Dinv = np.diag(1.0 / DEFAULT_FD_STEP)
    H = Dinv @ Q @ np.diag([100.0, 30.0, 10.0, 3.0, 1.0, 0.5]) @ Q.T @ Dinv
    return np.array([0.03, -0.02, 0.05, 0.4, -0.3, 0.2]), H


class TestPolish:
    def test_fd_derivatives_exact_on_a_quadratic(self, valley, rng):
        c, H = valley
        X = np.zeros((3, 7))
        X[:, :6] = c + rng.normal(scale=0.1, size=(3, 6))
        f, g, Hd = fd_gradient_hessian(_quadratic(c, H), X)
        np.testing.assert_allclose(Hd, np.broadcast_to(2 * H, Hd.shape), rtol=1e-6,
                                   atol=1e-6 * np.abs(H).max())
        np.testing.assert_allclose(g, 2 * (X[:, :6] - c) @ H, rtol=1e-6, atol=1e-8)

    def test_newton_reaches_the_minimum_of_a_valley(self, valley, rng):
        c, H = valley
        X = np.zeros((5, 7))
        X[:, :6] = c + rng.normal(scale=0.05, size=(5, 6)) * [1, 1, 1, 10, 10, 10]
        X[:, 6] = 100
        Xp, f, evals = newton_polish(_quadratic(c, H), X, iters=20, max_step=1e9)
        np.testing.assert_allclose(Xp[:, :6], np.broadcast_to(c, (5, 6)), atol=1e-6)
        assert (Xp[:, 6] == 100).all() and evals > 0

    def test_compass_never_worsens(self, valley, rng):
        c, H = valley
        X = np.zeros((4, 7))
        X[:, :6] = c + rng.normal(scale=0.2, size=(4, 6))
        fun = _quadratic(c, H)
        Xp, f, _ = polish(fun, X)
        assert np.all(f <= fun(X) + 1e-15)
        np.testing.assert_allclose(f, fun(Xp))


class TestSeeding:
    def test_grid_size(self):
        g = rotation_grid(25.0, 2.5)
        assert g.shape == (21 ** 3, 3) and np.abs(g).max() == 25.0

    def test_finds_the_rotation_of_a_synthetic_objective(self):
        target = np.array([0.1, -0.05, 0.0, 7.3, -12.1, 4.4])

        def f(X):
            return np.sum(((X[:, :6] - target) / [0.2, 0.2, 0.2, 3.0, 3.0, 3.0]) ** 2, axis=1)

        poses, vals = grid_seeds(f, 25.0, 1.5, 2.5, n=50, keep=3)
        np.testing.assert_allclose(poses[0], target, atol=1e-3)
        # Every polished candidate reaches the single minimum: duplicates are dropped.
        assert len(poses) == 1 and np.all(np.diff(vals) >= 0)


class TestNSGA2:
    class Toy:
        """Two objectives: distance of the pose to a target (worse with few points) and n."""

        def evaluate(self, X):
            d = np.linalg.norm(X[:, :6] - 1.0, axis=1)
            return np.column_stack([d + 5.0 / np.sqrt(X[:, 6]), X[:, 6]])

    def test_deterministic_and_front_is_non_dominated(self):
        s = SearchSettings(pop=40, gens=15, seed=7, bound_t_m=3, bound_r_deg=3)
        a = run_nsga2(self.Toy(), s, 10, 1000)
        b = run_nsga2(self.Toy(), s, 10, 1000)
        np.testing.assert_array_equal(a.X, b.X)
        X, F = front_of(a.pop_X, a.pop_F)
        np.testing.assert_array_equal(X, a.X)
        assert a.evaluations == 40 * 15 and a.generations == 15
        assert np.all(a.X[:, 6] == np.round(a.X[:, 6]))          # n is an integer
        assert a.X[:, 6].max() > 5 * a.X[:, 6].min()              # the front spans n

    def test_a_stop_request_ends_the_search_at_the_next_generation(self):
        """A stop whose KeyboardInterrupt was swallowed by the code that received it is taken
        before the next generation: the search raises SearchInterrupted with the last whole
        generation, and the request is cleared."""
        from paretocal.errors import STOP
        from paretocal.search.checkpoint import SearchInterrupted

        def progress(gen, total, best):
            if gen == 4:
                STOP.request()
        s = SearchSettings(pop=20, gens=15, seed=7, bound_t_m=3, bound_r_deg=3)
        with pytest.raises(SearchInterrupted) as info:
            run_nsga2(self.Toy(), s, 10, 1000, progress=progress)
        assert info.value.generation == 4 and not STOP.requested


class TestEngines:
    """The package's array engine and pymoo's algorithm object (benchmarks/pymoo_nsga.py) run
    the same NSGA-II."""

    @staticmethod
    def _pymoo():
        return load_benchmark("pymoo_nsga")

    def _settings(self, seed=3):
        return SearchSettings(pop=60, gens=25, seed=seed, bound_t_m=3, bound_r_deg=3)

    def _run(self, engine, seed=3):
        s = self._settings(seed)
        if engine == "pymoo":
            return self._pymoo().run_pymoo_nsga2(TestNSGA2.Toy(), s, 10, 1000)
        return run_nsga2(TestNSGA2.Toy(), s, 10, 1000)

    def test_both_converge_to_the_same_front(self):
        from pymoo.indicators.hv import HV

        ref = np.array([10.0, 1100.0])
        hv = {e: HV(ref_point=ref)(self._run(e).F) for e in ("lean", "pymoo")}
        best = HV(ref_point=ref)(np.column_stack([5.0 / np.sqrt(np.arange(10, 1001)),
                                                  np.arange(10, 1001)]))
        for e, v in hv.items():
            assert v > 0.9 * best, (e, v, best)
        assert abs(hv["lean"] - hv["pymoo"]) < 0.05 * best

    def test_pymoo_engine_is_deterministic(self):
        np.testing.assert_array_equal(self._run("pymoo").F, self._run("pymoo").F)

    def test_seeds_enter_the_initial_population(self):
        class Recorder(TestNSGA2.Toy):
            first = None

            def evaluate(self, X):
                if Recorder.first is None:
                    Recorder.first = X.copy()
                return super().evaluate(X)

        seeds = np.array([[0.1, 0.2, 0.3, 1.0, 2.0, -1.0]])
        s = SearchSettings(pop=40, gens=1, seed=0)
        run_nsga2(Recorder(), s, 10, 1000, seeds=seeds)
        X0 = Recorder.first
        assert np.any(np.all(X0[:, :6] == 0.0, axis=1))             # the zero correction
        assert np.any(np.all(np.isclose(X0[:, :6], seeds[0]), axis=1))


def test_survival_ranks_and_crowding_are_pymoos(rng):
    """The engine's survival takes pymoo's fronts (moocore's ranks, one stable sort) and its
    crowding distance (compiled, every front at once): the same values bit for bit, ties,
    duplicates and fronts of one or two points included."""
    from pymoo.operators.survival.rank_and_crowding.metrics import get_crowding_function
    from pymoo.util.nds.non_dominated_sorting import NonDominatedSorting

    from paretocal.search.engine import ArrayNSGA2

    engine = ArrayNSGA2(None, np.zeros(7), np.ones(7), 10, None)
    cd = get_crowding_function("cd")
    for trial in range(200):
        m = int(rng.integers(1, 120))
        F = rng.normal(size=(m, 2)).round(int(rng.integers(0, 3)))   # many ties
        if trial % 3 == 0:
            F[rng.integers(0, m, m // 3)] = F[0]                     # duplicates
        n_survive = int(rng.integers(1, m + 1))
        rank, crowd, keep = engine._survive(F, n_survive, np.random.default_rng(trial))
        fronts = NonDominatedSorting().do(F, n_stop_if_ranked=n_survive)
        assert len(keep) == n_survive
        ref_rank = np.concatenate([np.full(len(f), k) for k, f in enumerate(fronts)])
        ref_cd = np.concatenate([cd.do(F[f], n_remove=0) for f in fronts])
        ref_idx = np.concatenate(fronts)
        full = len(ref_idx) == n_survive
        if full:                                  # no split of the last front: all compared
            np.testing.assert_array_equal(keep, ref_idx)
            np.testing.assert_array_equal(rank, ref_rank)
            np.testing.assert_array_equal(crowd, ref_cd)
        else:                                     # the kept part of the split front
            where = {int(i): k for k, i in enumerate(ref_idx)}
            np.testing.assert_array_equal(crowd, ref_cd[[where[int(i)] for i in keep]])
            np.testing.assert_array_equal(rank, ref_rank[[where[int(i)] for i in keep]])


def test_a_front_polished_without_exploring_keeps_its_n():
    """``polish_front(explore=False)`` (the basin test's polish from one optimum) polishes the
    given solutions only: every n of the result is one of theirs, with fewer evaluations than
    the exploring polish (n grid, valley starts, cross-seeds), which adds n values."""
    from paretocal.search.front_polish import polish_front

    center = np.array([0.02, -0.01, 0.03, 0.4, -0.3, 0.2])

    class Bowl:
        def chamfer(self, X):
            d = X[:, :6] - center
            return {"f1": (d * d).sum(axis=1) + 1.0 / np.sqrt(X[:, 6])}

        def cost(self, X):
            return {"f2": X[:, 6].astype(float)}

    s = SearchSettings(bound_t_m=0.3, bound_r_deg=3)
    X = np.zeros((4, 7))
    X[:, 6] = [50, 100, 200, 400]
    F = np.column_stack([Bowl().chamfer(X)["f1"], X[:, 6]])
    Xa, Fa, ea = polish_front(Bowl(), X, F, s, 10, 1000, 4, explore=False)
    Xb, Fb, eb = polish_front(Bowl(), X, F, s, 10, 1000, 4)
    assert set(Xa[:, 6]) <= {50, 100, 200, 400} and ea < eb
    assert len(set(Xb[:, 6]) - {50, 100, 200, 400}) > 0
    np.testing.assert_allclose(Xa[:, :6], np.tile(center, (len(Xa), 1)), atol=2e-3)
