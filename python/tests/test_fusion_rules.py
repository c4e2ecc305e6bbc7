"""Fusion rules beyond CI (docs/fusion.md): ``edccif.fuse`` against independent
numpy implementations written from each paper's equations, and the rules in
the networks (``fusion=`` on run, Network, ModelNetwork, monte_carlo and the
scenario file).

Tolerances: the closed-form rules (fixed weights) agree to 1e-10 relative
(a few inversions of matrices with condition numbers up to ~1e4); the rules
with optimised weights are compared on the criterion they minimise, which must
be within 1e-7 relative of scipy's bounded minimiser (the oracle), and their
covariances within 1e-4 relative (a flat minimum leaves the weights loosely
determined). The consistency of each rule over random cases of its correlation
class, and where it ends, is tested in crates/edccif-core/tests/fusion_rules.rs.
"""

import pathlib
import re

import numpy as np
import pytest
from scipy.optimize import minimize, minimize_scalar

import edccif
from edccif import models

DOC = pathlib.Path(__file__).resolve().parents[2] / "docs" / "fusion.md"
inv = np.linalg.inv
RTOL = 1e-10


def spd(rng, n):
    a = rng.uniform(-1, 1, (n, n))
    q, _ = np.linalg.qr(a)
    return q @ np.diag(10 ** rng.uniform(-1.5, 1.5, n)) @ q.T


def cases(seed, count=40, k_range=(2, 4)):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        k = int(rng.integers(k_range[0], k_range[1] + 1))
        n = int(rng.integers(1, 6))
        xs = rng.uniform(-3, 3, (k, n))
        ps = np.array([spd(rng, n) for _ in range(k)])
        w = rng.uniform(0.05, 1.0, k)
        yield xs, ps, w


def close(a, b, rtol=RTOL):
    scale = max(1.0, np.abs(b).max())
    return np.abs(a - b).max() <= rtol * scale


# ---------------------------------------------------------------------------
# numpy oracles, from the papers' equations


def ci_oracle(xs, ps, w):
    """Covariance intersection (Julier & Uhlmann 1997): P⁻¹ = Σ ω_j P_j⁻¹,
    P⁻¹x = Σ ω_j P_j⁻¹ x_j, ω normalised."""
    w = np.asarray(w) / np.sum(w)
    y = sum(wj * inv(p) for wj, p in zip(w, ps))
    yv = sum(wj * inv(p) @ x for wj, x, p in zip(w, xs, ps))
    P = inv(y)
    return P @ yv, P


def crit(P, criterion):
    return np.trace(P) if criterion == "trace" else np.linalg.slogdet(P)[1]


def ci_opt_oracle(xs, ps, criterion):
    """CI with the weights minimising tr P or det P: scipy's bounded scalar
    minimiser for two inputs, SLSQP on the simplex from every vertex and the
    centre for more."""
    k = len(xs)

    def f(w):
        w = np.clip(w, 0, None)
        return crit(ci_oracle(xs, ps, w / w.sum())[1], criterion)

    if k == 2:
        r = minimize_scalar(lambda t: f(np.array([t, 1 - t])), bounds=(0, 1), method="bounded",
                            options={"xatol": 1e-12})
        return min(r.fun, f(np.array([1.0, 0.0])), f(np.array([0.0, 1.0])))
    best = np.inf
    for start in [np.full(k, 1 / k)] + list(np.eye(k) * 0.98 + 0.01):
        r = minimize(f, start, method="SLSQP", bounds=[(0, 1)] * k,
                     constraints=[{"type": "eq", "fun": lambda w: w.sum() - 1}],
                     options={"ftol": 1e-15, "maxiter": 500})
        best = min(best, r.fun)
    return min([best] + [f(e) for e in np.eye(k)])


def ici_pair_oracle(a, A, b, B, omega):
    """Inverse covariance intersection (Noack, Sijs, Reinhardt, Hanebeck,
    Automatica 2017): C⁻¹ = A⁻¹ + B⁻¹ − (ωA + (1−ω)B)⁻¹,
    K = C (A⁻¹ − ω S⁻¹), L = C (B⁻¹ − (1−ω) S⁻¹), c = K a + L b."""
    S = inv(omega * A + (1 - omega) * B)
    C = inv(inv(A) + inv(B) - S)
    K = C @ (inv(A) - omega * S)
    L = C @ (inv(B) - (1 - omega) * S)
    return K @ a + L @ b, C


def ici_oracle(xs, ps, w, criterion=None):
    """ICI of K estimates, pairwise in order: ω the new input's share of the
    weights (fixed), or minimising the criterion (scipy's bounded minimiser,
    as the authors' reference implementation uses fminbnd)."""
    w = np.asarray(w) / np.sum(w)
    c, C, W = xs[0], ps[0], w[0]
    for x, p, wj in zip(xs[1:], ps[1:], w[1:]):
        if criterion is None:
            omega = wj / (W + wj)
        else:
            def f(o, c=c, C=C, x=x, p=p):
                return crit(ici_pair_oracle(c, C, x, p, o)[1], criterion)

            r = minimize_scalar(f, bounds=(0, 1), method="bounded", options={"xatol": 1e-12})
            omega = r.x
            for end in (0.0, 1.0):
                if crit(ici_pair_oracle(c, C, x, p, end)[1], criterion) < r.fun:
                    omega = end
        c, C = ici_pair_oracle(c, C, x, p, omega)
        W += wj
    return c, C


def split_oracle(xs, ps, w, i_ind, I_ind):
    """Split CI in information form: the dependent estimates intersected, the
    independent information added once: P⁻¹ = Σ ω_j P_j⁻¹ + I, P⁻¹x = Σ ω_j P_j⁻¹x_j + i."""
    w = np.asarray(w) / np.sum(w)
    y = sum(wj * inv(p) for wj, p in zip(w, ps)) + I_ind
    yv = sum(wj * inv(p) @ x for wj, x, p in zip(w, xs, ps)) + i_ind
    P = inv(y)
    return P @ yv, P


def ei_pair_oracle(xi, Pi, xj, Pj, zeta=1e-10):
    """Ellipsoidal intersection (Sijs & Lazar, Automatica 2012, eqs. 8–16):
    eigen-decomposition of Pi, then of the whitened Pj; mutual covariance
    Γ = T diag(max(1, d)) Tᵀ, mutual mean from W_i, W_j with η; fused
    P = (Pi⁻¹ + Pj⁻¹ − Γ⁻¹)⁻¹, x = P (Pi⁻¹ xi + Pj⁻¹ xj − Γ⁻¹ γ)."""
    di, Si = np.linalg.eigh(Pi)
    Dr = np.diag(np.sqrt(di))
    Dri = np.diag(1 / np.sqrt(di))
    dj, Sj = np.linalg.eigh(Dri @ Si.T @ Pj @ Si @ Dri)
    T = Si @ Dr @ Sj
    dg = np.maximum(1.0, dj)
    Gamma = T @ np.diag(dg) @ T.T
    eta = np.where(np.abs(dj - 1) < 10 * zeta, zeta, 0.0)
    Wi = np.diag(1 / dj - 1 / dg + eta)
    Wj = np.diag(1 - 1 / dg + eta)
    mui, muj = inv(T) @ xi, inv(T) @ xj
    gamma = T @ inv(Wi + Wj) @ (Wi @ mui + Wj @ muj)
    P = inv(inv(Pi) + inv(Pj) - inv(Gamma))
    return P @ (inv(Pi) @ xi + inv(Pj) @ xj - inv(Gamma) @ gamma), P


def ei_oracle(xs, ps):
    c, C = xs[0], ps[0]
    for x, p in zip(xs[1:], ps[1:]):
        c, C = ei_pair_oracle(c, C, x, p)
    return c, C


# ---------------------------------------------------------------------------
# edccif.fuse against the oracles


def test_rule_names():
    assert edccif.FUSION_RULES == tuple(edccif.fusion_rules())
    assert edccif.FUSION_RULES[0] == "ci"
    assert {"ici", "ici-trace", "split-ci", "ci-trace", "ei-unsafe"} <= set(edccif.FUSION_RULES)
    # a rule without a guarantee only behind a name that says so
    assert [r for r in edccif.FUSION_RULES if r.startswith("ei")] == ["ei-unsafe"]
    with pytest.raises(edccif.UnknownOptionError, match="ei-unsafe"):
        edccif.fuse(np.zeros((2, 2)), np.array([np.eye(2)] * 2), "ei")


def test_ci_matches_the_oracle_and_ci_fuse():
    for xs, ps, w in cases(1):
        x, P = edccif.fuse(xs, ps, "ci", weights=w)
        xo, Po = ci_oracle(xs, ps, w)
        assert close(x, xo) and close(P, Po)
        x2, P2, _ = edccif.ci_fuse(xs, ps, weights=w)
        assert close(x, x2, 1e-13) and close(P, P2, 1e-13)


@pytest.mark.parametrize("criterion", ["trace", "det"])
def test_ci_optimised_reaches_the_oracles_minimum(criterion):
    for xs, ps, _ in cases(2, count=15, k_range=(2, 3)):
        x, P = edccif.fuse(xs, ps, f"ci-{criterion}")
        best = ci_opt_oracle(xs, ps, criterion)
        got = crit(P, criterion)
        # the minimum, not above scipy's (nor far below it: the same problem)
        assert got <= best + 1e-7 * abs(best) + 1e-12, (got, best)
        assert got >= best - 1e-6 * abs(best) - 1e-12, (got, best)
        # and never worse than the starting (uniform) weights
        assert got <= crit(ci_oracle(xs, ps, np.ones(len(xs)))[1], criterion) + 1e-12


def test_ici_matches_the_oracle():
    for xs, ps, w in cases(3):
        x, P = edccif.fuse(xs, ps, "ici", weights=w)
        xo, Po = ici_oracle(xs, ps, w)
        assert close(x, xo) and close(P, Po), (np.abs(P - Po).max(), np.abs(P).max())


@pytest.mark.parametrize("criterion", ["trace", "det"])
def test_ici_optimised_matches_the_oracle(criterion):
    for xs, ps, w in cases(4, count=20, k_range=(2, 2)):
        x, P = edccif.fuse(xs, ps, f"ici-{criterion}", weights=w)
        xo, Po = ici_oracle(xs, ps, w, criterion)
        assert crit(P, criterion) <= crit(Po, criterion) + 1e-7 * abs(crit(Po, criterion)) + 1e-12
        assert close(P, Po, 1e-4) and close(x, xo, 1e-4)
    # more inputs: pairwise, each pair's ω minimising the criterion
    for xs, ps, w in cases(5, count=10, k_range=(3, 4)):
        _, P = edccif.fuse(xs, ps, f"ici-{criterion}", weights=w)
        _, Po = ici_oracle(xs, ps, w, criterion)
        assert close(P, Po, 1e-4)


def test_split_ci_matches_the_oracle():
    rng = np.random.default_rng(6)
    for xs, ps, w in cases(6):
        n = xs.shape[1]
        h = rng.uniform(-1, 1, (2, n))
        I_ind = h.T @ np.diag(10 ** rng.uniform(-1, 1, 2)) @ h
        i_ind = rng.uniform(-1, 1, n)
        x, P = edccif.fuse(xs, ps, "split-ci", weights=w, independent=(i_ind, I_ind))
        xo, Po = split_oracle(xs, ps, w, i_ind, I_ind)
        assert close(x, xo) and close(P, Po)
        # without the independent part split CI is CI
        x1, P1 = edccif.fuse(xs, ps, "split-ci", weights=w)
        assert close(P1, ci_oracle(xs, ps, w)[1])


def _with_independent(x, P, i_ind, I_ind):
    """Adds independent information once to a fused estimate (the split rules'
    second term, Julier & Uhlmann 2001): Y = P⁻¹ + I, y = P⁻¹x + i."""
    Y = inv(P) + I_ind
    Pf = inv(Y)
    return Pf @ (inv(P) @ x + i_ind), Pf


def _independent(rng, n):
    h = rng.uniform(-1, 1, (2, n))
    return rng.uniform(-1, 1, n), h.T @ np.diag(10 ** rng.uniform(-1, 1, 2)) @ h


def test_split_ici_matches_the_oracle():
    # the dependent parts by ICI (pairwise, node order), the independent part once
    rng = np.random.default_rng(16)
    for xs, ps, w in cases(16):
        i_ind, I_ind = _independent(rng, xs.shape[1])
        x, P = edccif.fuse(xs, ps, "split-ici", weights=w, independent=(i_ind, I_ind))
        xo, Po = _with_independent(*ici_oracle(xs, ps, w), i_ind, I_ind)
        assert close(x, xo) and close(P, Po), (np.abs(P - Po).max(), np.abs(Po).max())


@pytest.mark.parametrize("criterion", ["trace", "det"])
def test_split_optimised_rules_match_the_oracle(criterion):
    # the weights minimise the criterion of the dependent parts' fusion (scipy's
    # bounded minimiser), the independent part is then added once; tolerance
    # 1e-4 relative as for the other optimised rules (flat minimum)
    rng = np.random.default_rng(17)
    for xs, ps, w in cases(17, count=20, k_range=(2, 2)):
        i_ind, I_ind = _independent(rng, xs.shape[1])

        def f(t, xs=xs, ps=ps):
            return crit(ci_oracle(xs, ps, np.array([t, 1 - t]))[1], criterion)

        r = minimize_scalar(f, bounds=(0, 1), method="bounded", options={"xatol": 1e-12})
        t = min([(r.fun, r.x), (f(0.0), 0.0), (f(1.0), 1.0)])[1]
        xo, Po = _with_independent(*ci_oracle(xs, ps, np.array([t, 1 - t])), i_ind, I_ind)
        x, P = edccif.fuse(xs, ps, f"split-ci-{criterion}", weights=w, independent=(i_ind, I_ind))
        assert close(P, Po, 1e-4) and close(x, xo, 1e-4), (np.abs(P - Po).max(), np.abs(Po).max())
        xo, Po = _with_independent(*ici_oracle(xs, ps, w, criterion), i_ind, I_ind)
        x, P = edccif.fuse(xs, ps, f"split-ici-{criterion}", weights=w, independent=(i_ind, I_ind))
        assert close(P, Po, 1e-4) and close(x, xo, 1e-4), (np.abs(P - Po).max(), np.abs(Po).max())


def test_ei_matches_the_oracle():
    for xs, ps, _ in cases(7):
        x, P = edccif.fuse(xs, ps, "ei-unsafe")
        xo, Po = ei_oracle(xs, ps)
        assert close(x, xo, 1e-9) and close(P, Po, 1e-9), (np.abs(P - Po).max(), np.abs(x - xo).max())


def test_ei_equals_the_largest_ellipsoid():
    # EI's covariance is the largest ellipsoid inside both inputs' (Benaskeur's
    # and Gustafsson's safe fusion): the covariance of the joint diagonalisation
    # with min(1, d) in the whitened basis
    rng = np.random.default_rng(8)
    for _ in range(20):
        A, B = spd(rng, 3), spd(rng, 3)
        L = np.linalg.cholesky(A)
        d, U = np.linalg.eigh(inv(L) @ B @ inv(L).T)
        T = L @ U
        le = T @ np.diag(np.minimum(1, d)) @ T.T
        _, P = edccif.fuse(np.zeros((2, 3)), np.array([A, B]), "ei-unsafe")
        assert close(P, le, 1e-9)


def test_fuse_errors():
    xs, ps = np.zeros((2, 2)), np.array([np.eye(2), np.eye(2)])
    with pytest.raises(edccif.NotPositiveDefiniteError, match=r"Ps\[1\]"):
        edccif.fuse(xs, np.array([np.eye(2), -np.eye(2)]), "ici")
    with pytest.raises(edccif.ParameterError, match="weights"):
        edccif.fuse(xs, ps, "ci", weights=[-1.0, 1.0])
    with pytest.raises(edccif.ShapeError, match="independent"):
        edccif.fuse(xs, ps, "split-ci", independent=(np.zeros(3), np.eye(2)))
    with pytest.raises(edccif.ShapeError, match="Ps"):
        edccif.fuse(xs, np.eye(2), "ci")


# ---------------------------------------------------------------------------
# The rules in the networks


@pytest.fixture(scope="module")
def short4():
    sc = edccif.Scenario.paper(nodes=4).replace(steps=60)
    return sc, sc.simulate(seed=5)


def test_default_is_the_papers_ci(short4):
    sc, (_, z, x0) = short4
    a = edccif.run("edc-cif", sc, z, x0=x0)
    for same in ({"fusion": "ci"}, {"fusion": "diffusion-ci"}):
        b = edccif.run("edc-cif", sc, z, x0=x0, **same)
        np.testing.assert_array_equal(a.estimates, b.estimates)
    assert sc.fusion == "ci"


@pytest.mark.parametrize("rule", ["ci-trace", "ici", "ici-trace", "split-ci", "split-ci-det", "ei-unsafe"])
def test_every_rule_runs_and_the_scenario_key_equals_the_option(short4, rule):
    sc, (truth, z, x0) = short4
    r = edccif.run("edc-cif", sc, z, x0=x0, fusion=rule)
    assert np.isfinite(r.estimates).all() and r.guard_fallbacks == 0
    # the scenario's `fusion` (TOML) gives the same numbers as the run option
    sc2 = edccif.Scenario.from_toml_str(sc.replace(fusion=rule).to_toml())
    assert sc2.fusion == rule and f'fusion = "{rule}"' in sc2.to_toml()
    r2 = edccif.run("edc-cif", sc2, z, x0=x0)
    np.testing.assert_array_equal(r.estimates, r2.estimates)
    # and a run option replaces the scenario's rule
    r3 = edccif.run("edc-cif", sc2, z, x0=x0, fusion="ci")
    np.testing.assert_array_equal(r3.estimates, edccif.run("edc-cif", sc, z, x0=x0).estimates)
    # the same numbers stepping a Network, on two threads, and from the models
    net = edccif.Network(sc, "edc-cif", x0=x0, fusion=rule)
    for zk in z:
        net.step(zk)
    np.testing.assert_array_equal(net.estimates, r.estimates[-1])
    par = edccif.run("edc-cif", sc, z, x0=x0, fusion=rule, threads=2)
    np.testing.assert_array_equal(par.estimates, r.estimates)
    ct = models.CoordinatedTurn(0.5, 1e-4)
    rpa = [models.RangePitchAzimuth(s, 0.1, 0.01) for s in sc.sensors]
    mn = edccif.ModelNetwork(ct, rpa, "edc-cif", x0=x0, P0=sc.p0, weights=sc.weights, dt=sc.dt, fusion=rule)
    res = mn.run([z[:, i] for i in range(4)])
    np.testing.assert_array_equal(res.estimates, r.estimates)


def test_on_the_complete_graph_every_rule_is_the_centralised_filter(short4):
    # every node adapts with every contribution: identical inputs, which every
    # rule returns unchanged
    sc, (_, z, x0) = short4
    full = sc.replace(topology="complete")
    ref = edccif.run("dc-cif", full, z, x0=x0)
    for rule in edccif.FUSION_RULES:
        r = edccif.run("dc-cif", full, z, x0=x0, fusion=rule)
        np.testing.assert_allclose(r.estimates, ref.estimates, rtol=0, atol=1e-8, err_msg=rule)


def test_monte_carlo_and_errors(short4):
    sc, (_, z, x0) = short4
    variants = [{"algorithm": "edc-cif", "fusion": "split-ci", "label": "EDC-CIF split-ci"}, "edc-cif"]
    mc = edccif.monte_carlo(sc.replace(steps=30), variants, runs=2, progress=False)
    a, b = mc.to_dict()["variants"]
    assert a["errors"]["pos_rmse"] != b["errors"]["pos_rmse"]
    with pytest.raises(edccif.UnknownOptionError, match="split-ci"):
        edccif.run("edc-cif", sc, z, x0=x0, fusion="split")
    with pytest.raises(edccif.UnknownOptionError, match="ici"):
        sc.replace(fusion="consensus")
    with pytest.raises(edccif.ScenarioError, match="fusion"):
        sc.replace(fusion=3)
    # a rule makes a row combine by diffusion: a covariance-form (consensus) row cannot
    with pytest.raises(edccif.ParameterError, match="diffusion needs the CIF"):
        edccif.Network(sc, "ec-ckf", x0=x0, fusion="ici").step(z[0])
    # the phase-by-phase Node combines with the paper's CI only, and says so
    with pytest.raises(edccif.ParameterError, match="Node"):
        edccif.Node(sc, "edc-cif", 0, fusion="ici")
    with pytest.raises(edccif.ParameterError, match="Node"):
        edccif.Node(sc.replace(fusion="ici"), "edc-cif", 0)


def test_fusion_doc_example_runs():
    text = DOC.read_text(encoding="utf-8")
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert blocks, "docs/fusion.md has no python example"
    for block in blocks:
        exec(compile(block, str(DOC), "exec"), {})


def test_planar_scenario_doctest_and_bounds():
    # the 2-D mixed-sensor scenario of the fusion front: its example runs, and
    # on the complete graph every node holds the centralised estimate
    import doctest

    import edccif.planar as planar

    assert doctest.testmod(planar).failed == 0
    ring = planar.PlanarCell("dc-cif", None, None, None, "ring", runs=3, steps=40).run()
    full = planar.PlanarCell("dc-cif", None, None, None, "complete", runs=3, steps=40).run()
    assert full["pos_rmse"] < ring["pos_rmse"]
    assert ring["trigger_rate"] == 1.0 and ring["floats_s2e"] == 10.0  # m = 2 + 1 + 2 + 2 + 1 + 2
    with pytest.raises(edccif.ParameterError, match="topology"):
        planar.weights("star")


@pytest.mark.parametrize("rule", ["split-ci", "split-ci-trace", "split-ci-det"])
def test_split_ci_is_consistent_in_a_linear_gaussian_network(rule):
    # the network is in split CI's class when the contributions are exact
    # measurements with independent noise: linear position sensors, the
    # constant-velocity model, every measurement sent or the stochastic
    # trigger's exact silence; the NEES averaged over 50 runs is not above its
    # 95 % band (χ² with 6·50 degrees of freedom)
    from edccif.sweep import chi2_band

    sc = edccif.Scenario.paper(nodes=6).replace(
        motion={"kind": "constant-velocity", "q": 0.5}, measurement={"kind": "position", "sigma": [0.3, 0.3, 0.3]},
        x0=[5.0, 0.0, 1.0, 0.0, 1.5, 0.1], p0_diag=[0.01] * 6, steps=100)
    _, hi = chi2_band(6 * 50, 50)
    for trigger in ("always", "stochastic"):
        mc = edccif.monte_carlo(sc, [{"algorithm": "edc-cif", "fusion": rule, "trigger": trigger}], runs=50,
                                progress=False)
        nees = mc.to_dict()["variants"][0]["errors"]["nees"]
        assert nees <= hi, (rule, trigger, nees, hi)
