"""Eigen paths on one factorisation: shift-invert ARPACK (the code's path) against block subspace iteration.

Both reuse the PARDISO/SuperLU factorisation of K - sigma M of the original plate at one accuracy-control mesh
level; the block method (Rayleigh-Ritz subspace iteration, p vectors per solve) is run until its six
frequencies agree with ARPACK's to 1e-9.  Prints one JSON object: times, solve counts (right-hand sides),
the cost of one block solve against one vector solve, and the ratios.  docs/fem.md, speed.

    python bench/bench_eigen.py [LEVEL]
"""
import time, sys, json
import numpy as np
import scipy.linalg as la
from workflow.models.plate import ORIGINAL_PLATE as plate
from workflow.models.fem.accuracy import mesh_for_level
from workflow.models.fem.evaluate import discretise
from workflow.models.fem.modes import shift_invert_modes, rigid_translation
from workflow.models.fem.solvers import factorise
from workflow.models import analytical


def main():
    level = int(sys.argv[1]) if len(sys.argv) > 1 else 8
    s = mesh_for_level(plate, level)
    _, system, _ = discretise(plate, 15.0, s)
    K, M = system.stiffness, system.mass
    shift = (2 * np.pi * float(analytical.resonance_frequency(plate))) ** 2
    t = time.perf_counter(); factor = factorise(K - shift * M); t_fact = time.perf_counter() - t
    calls = {"n": 0, "rhs": 0}
    def counted(b):
        calls["n"] += 1
        calls["rhs"] += 1 if b.ndim == 1 else b.shape[1]
        return factor.solve(b)

    t = time.perf_counter(); ref = shift_invert_modes(system, shift, counted, 6); t_arpack = time.perf_counter() - t
    arpack = dict(calls); f_ref = np.sqrt(ref.eigenvalues) / 2 / np.pi
    # single-solve and 12-rhs block solve timing
    b = np.random.default_rng(0).standard_normal((K.shape[0], 12))
    t = time.perf_counter(); [factor.solve(b[:, 0]) for _ in range(5)]; t1 = (time.perf_counter() - t) / 5
    t = time.perf_counter(); factor.solve(b); t12 = time.perf_counter() - t
    out = {"level": level, "dofs": K.shape[0], "factorise_s": t_fact, "arpack_s": t_arpack, "arpack_solves": arpack["n"], "solve_1rhs_s": t1, "solve_12rhs_s": t12}
    rigid = rigid_translation(system); rm = M @ rigid
    for p in (8, 12):
        calls.update(n=0, rhs=0)
        rng = np.random.default_rng(1)
        X = rng.standard_normal((K.shape[0], p))
        t = time.perf_counter()
        for it in range(60):
            Y = counted(M @ X); Y -= np.outer(rigid, rm @ Y)
            Kr = Y.T @ (K @ Y); Mr = Y.T @ (M @ Y)
            lam, Q = la.eigh(Kr, Mr)
            order = np.argsort(np.abs(lam - shift)); lam, Q = lam[order], Q[:, order]
            X = Y @ Q
            f = np.sqrt(np.sort(lam[:6])) / 2 / np.pi
            if np.max(np.abs(f / f_ref - 1)) < 1e-9:
                break
        elapsed = time.perf_counter() - t
        out[f"subspace_p{p}"] = {"s": elapsed, "time_over_arpack": elapsed / t_arpack, "iterations": it + 1, "rhs": calls["rhs"], "max_rel_f_err": float(np.max(np.abs(f / f_ref - 1)))}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
