"""What a fit's statistics can and cannot separate: the identifiability report of every least-squares fit.

The least squares (``sampler='ls'``) already holds the Jacobian J = d r / d u of its
standardised residuals r (each of unit variance, :func:`evstwin.tune.counts.chi2_residuals`)
with respect to the fitted parameters u in their [0, 1] coordinates (log-scaled where the
bound is). Linearised at the best point, the estimate's covariance is

    C = (J^T J)^-1,

its correlation matrix R_ij = C_ij / sqrt(C_ii C_jj), and the directions the statistics barely
constrain are the eigenvectors of J^T J with the smallest eigenvalues lambda: along such a
unit vector v the estimate's standard deviation is 1 / sqrt(lambda). Two parameters with
|R_ij| > :data:`evstwin.tune.options.CORRELATION_WARN` cannot be told apart by these
statistics: a change of one is undone by a change of the other (the threshold / dark-current
valley: R(theta_on, dark rate) near -1 on counts alone). Each parameter's standard error
sqrt(C_ii), marginalised over the others, gives the fit's default interval u_best +- sqrt(C_ii).

Left out (the calibrated intervals of ``FitOptions.intervals`` include them): the
correlations between statistics (they share events), how far the search stopped from the
minimum, and the curvature beyond the forward-difference step. Correlations are unchanged by
each parameter's scale, so R is the same in the parameters' own units.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .options import CORRELATION_WARN

POORLY_CONSTRAINED_SD = 0.1
"""A direction along which the estimate's standard deviation exceeds this share of the
bounds' (log) widths is reported as poorly constrained (0.1: a factor of 2.5 of a dark rate
over its default four decades, 1.3 of a threshold)."""

RIDGE = 1e-12
"""Eigenvalues of J^T J below this share of the largest count as zero: those directions are
unconstrained (their standard deviation is reported as infinite), and the covariance is
taken on the rest."""


def short(key: str) -> str:
    """A parameter's name without its section (``pixel.theta_on`` -> ``theta_on``)."""
    return key.split(".", 1)[1] if key.startswith("pixel.") else key


@dataclass(frozen=True)
class Identifiability:
    """The identifiability report of one fit (see the module): ``params`` (scenario keys),
    ``correlation`` (n, n; nan for an unconstrained parameter), ``sd_unit`` (n,) the
    standard errors in the [0, 1] coordinates (inf: unconstrained), ``eigenvalues``
    (ascending) and ``eigenvectors`` (columns) of J^T J, and ``source``, where the Jacobian
    came from."""

    params: list[str]
    correlation: np.ndarray = field(repr=False)
    sd_unit: np.ndarray = field(repr=False)
    eigenvalues: np.ndarray = field(repr=False)
    eigenvectors: np.ndarray = field(repr=False)
    source: str = ""

    @property
    def correlated_pairs(self) -> list[tuple[str, str, float]]:
        """(a, b, r) for every pair with |r| > :data:`CORRELATION_WARN`, strongest first."""
        n = len(self.params)
        pairs = [(self.params[i], self.params[j], float(self.correlation[i, j]))
                 for i in range(n) for j in range(i + 1, n)
                 if math.isfinite(self.correlation[i, j]) and abs(self.correlation[i, j]) > CORRELATION_WARN]
        return sorted(pairs, key=lambda p: -abs(p[2]))

    @property
    def unconstrained(self) -> list[str]:
        """The parameters no statistic moves with."""
        return [p for p, s in zip(self.params, self.sd_unit) if not math.isfinite(s)]

    def weak_directions(self) -> list[tuple[float, dict[str, float]]]:
        """(standard deviation along it, {parameter: component}) for each eigen-direction
        whose standard deviation exceeds :data:`POORLY_CONSTRAINED_SD` (the weakest first), or
        the weakest alone when none does. Components below 0.1 are left out; the largest is
        made positive."""
        out = []
        for k in range(len(self.eigenvalues)):
            lam = float(self.eigenvalues[k])
            sd = 1.0 / math.sqrt(lam) if lam > 0 else math.inf
            if k > 0 and not sd > POORLY_CONSTRAINED_SD:
                break
            v = self.eigenvectors[:, k]
            v = v * (1.0 if v[np.argmax(np.abs(v))] > 0 else -1.0)
            out.append((sd, {p: float(c) for p, c in zip(self.params, v) if abs(c) >= 0.1}))
        return out

    def warnings(self) -> list[str]:
        """One line per pair that cannot be told apart and per unconstrained parameter, saying
        what to do."""
        lines = []
        for a, b, r in self.correlated_pairs:
            lines.append(f"{short(a)} and {short(b)} cannot be told apart by these statistics (r = {r:+.2f}): "
                         f"fix one of them (--set {a}=VALUE and leave it out of --params) or give a longer recording")
        for p in self.unconstrained:
            lines.append(f"{short(p)} is not constrained: no statistic moves with it; fix it (--set {p}=VALUE "
                         "and leave it out of --params)")
        return lines

    def to_text(self) -> str:
        """The correlation matrix, the weak directions and the warnings, for a terminal."""
        names = [short(p) for p in self.params]
        width = max(8, *(len(n) for n in names))
        lines = [f"identifiability ({self.source}): correlation of the estimates"]
        lines.append(" " * (width + 2) + " ".join(f"{n[:8]:>8}" for n in names))
        for i, n in enumerate(names):
            cells = " ".join("     nan" if not math.isfinite(c) else f"{c:+8.2f}" for c in self.correlation[i])
            lines.append(f"  {n:<{width}}{cells}")
        for sd, comp in self.weak_directions():
            along = " ".join(f"{c:+.2f} {short(p)}" for p, c in sorted(comp.items(), key=lambda kv: -abs(kv[1])))
            what = "poorly constrained" if sd > POORLY_CONSTRAINED_SD else "weakest"
            sd_text = "inf" if not math.isfinite(sd) else f"{sd:.3g}"
            lines.append(f"  {what} direction: sd {sd_text} of the bounds' (log) widths along {along}")
        lines += [f"warning: {w}" for w in self.warnings()]
        return "\n".join(lines)

    def to_json_dict(self) -> dict[str, Any]:
        def num(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None

        return {
            "source": self.source,
            "params": list(self.params),
            "correlation": [[num(c) for c in row] for row in self.correlation],
            "sd_unit": [num(s) for s in self.sd_unit],
            "eigenvalues": [num(v) for v in self.eigenvalues],
            "weak_directions": [{"sd_unit": num(sd), "along": comp} for sd, comp in self.weak_directions()],
            "correlated_pairs": [{"a": a, "b": b, "r": r} for a, b, r in self.correlated_pairs],
            "unconstrained": self.unconstrained,
            "warnings": self.warnings(),
        }


def identifiability(jacobian: np.ndarray, params: Sequence[str], source: str = "") -> Identifiability:
    """The report (see the module) of the standardised residuals' Jacobian (S, n) over the
    fitted ``params``. A parameter whose column is zero is unconstrained (sd inf, correlations
    nan); directions whose eigenvalue is below :data:`RIDGE` of the largest are unconstrained
    too, and the covariance is taken on the others (a pair moving only together then shows
    r = +-1)."""
    j = np.asarray(jacobian, np.float64)
    n = len(params)
    if j.ndim != 2 or j.shape[1] != n:
        raise ValueError(f"identifiability: jacobian must be (S, {n}); got {j.shape}")
    if not np.all(np.isfinite(j)):
        raise ValueError("identifiability: the jacobian has non-finite entries")
    h = j.T @ j
    lam, vec = np.linalg.eigh(h)
    top = float(lam[-1]) if n else 0.0
    keep = lam > RIDGE * top if top > 0 else np.zeros(n, bool)
    cov = (vec[:, keep] / lam[keep]) @ vec[:, keep].T
    moved = np.any(j != 0.0, axis=0)
    # A direction with no information: the parameters with a share of it are unconstrained.
    free = np.any(np.abs(vec[:, ~keep]) > 1e-6, axis=1) if np.any(~keep) else np.zeros(n, bool)
    var = np.diag(cov).copy()
    sd = np.where(free | ~moved, math.inf, np.sqrt(np.maximum(var, 0.0)))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.sqrt(np.outer(var, var))
    if np.any(~keep):
        # A pair moving only together: their correlation is that of the null direction (+-1:
        # along it the residuals do not change, so the estimates' spread is all there).
        null = vec[:, ~keep]
        for a in range(n):
            for b in range(n):
                if moved[a] and moved[b] and free[a] and free[b]:
                    na, nb = null[a], null[b]
                    dot = float(na @ nb)
                    norm = float(np.linalg.norm(na) * np.linalg.norm(nb))
                    corr[a, b] = dot / norm if a != b else 1.0
    corr[~moved, :] = math.nan
    corr[:, ~moved] = math.nan
    np.fill_diagonal(corr, np.where(moved, 1.0, math.nan))
    lam_sorted = np.maximum(lam, 0.0)
    lam_sorted[~keep] = 0.0
    return Identifiability(list(params), np.clip(corr, -1.0, 1.0), sd, lam_sorted, vec, source)
