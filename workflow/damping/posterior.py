"""The Q(v) posterior as a file: what ``tactile fit-damping`` writes and ``--damping`` reads.

``posterior.npz`` (numpy, no pickles) holds the law's name, its parameters' posterior
samples in natural units (``q0`` [-], ``alpha`` [s^2/m^2 or s/m], ...), and the full sampled
coordinates for reference.  A stacked (model-averaged) posterior has the law ``stacking``
(:class:`~workflow.damping.laws.StackedLaws`): a ``component`` column and every mixed law's
parameters.
"""

import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Dict

import numpy as np

from workflow.damping.laws import (
    LAWS,
    POSTERIOR_LAWS,
    STACKED_COMPONENTS,
    StackedLaws,
    ThresholdLoss,
    parameter_names,
    scaled_parameters,
)
from workflow.damping.likelihood import Q0_RANGE
from workflow.errors import InputFileError
from workflow.inputfiles import MAX_POSTERIOR_BYTES, open_input

POSTERIOR_FILE = "posterior.npz"
"""File name of the posterior in a fit's output folder."""
MAX_ALPHA = 1e12
"""Largest accepted loss coefficient alpha [s^2/m^2 or s/m]: the fit's prior bound for the quadratic law
at the smallest peak velocity a log may have (1e-6 m/s)."""
SCALED_RANGES = {"q0": Q0_RANGE, "alpha": (0.0, MAX_ALPHA)}
"""Accepted ranges of the parameters a law-shape discrepancy scales (:func:`with_shape_discrepancy` keeps them)."""


@dataclass(frozen=True)
class DampingPosterior:
    """Posterior samples of a Q(v) law's parameters.

    Attributes
    ----------
    law_name : str
        A key of :data:`~workflow.damping.laws.POSTERIOR_LAWS`.
    parameters : dict
        Parameter name -> samples (M,), natural units.
    source : str
        Where it was read from (or ``"fit"``).
    """

    law_name: str
    parameters: Dict[str, np.ndarray]
    source: str = "fit"

    @property
    def n_samples(self) -> int:
        return len(next(iter(self.parameters.values())))

    def component_shares(self) -> Dict[str, float]:
        """A stacked posterior's law name -> share of its samples, largest first (ties in
        :data:`~workflow.damping.laws.STACKED_COMPONENTS` order); one law: {its name: 1}."""
        if self.law_name != StackedLaws.name:
            return {self.law_name: 1.0}
        counts = np.bincount(self.parameters["component"].astype(int), minlength=len(STACKED_COMPONENTS))
        order = sorted((i for i, c in enumerate(counts) if c), key=lambda i: (-counts[i], i))
        return {STACKED_COMPONENTS[i]: float(counts[i] / counts.sum()) for i in order}

    @property
    def description(self) -> str:
        """The law for people: its name, or for a stacked posterior "mixture of <law> <share> %, ..." (shares of the
        samples, largest first)."""
        if self.law_name != StackedLaws.name:
            return self.law_name
        return "mixture of " + ", ".join(f"{name} {100 * share:.0f} %" for name, share in self.component_shares().items())

    def median_law(self):
        """The law at the marginal posterior medians of its parameters; for a stacked posterior, the
        median law of its most frequent component (the first of :meth:`component_shares`)."""
        if self.law_name != StackedLaws.name:
            return LAWS[self.law_name](**{name: float(np.median(v)) for name, v in self.parameters.items()})
        name = next(iter(self.component_shares()))
        mine = self.parameters["component"] == STACKED_COMPONENTS.index(name)
        return LAWS[name](**{p: float(np.median(self.parameters[f"{name}_{p}"][mine])) for p in parameter_names(LAWS[name])})

    def draws(self, n: int, seed: int = 0):
        """``n`` posterior draws (without replacement when possible) as one law with (n,) parameters."""
        rng = np.random.default_rng(seed)
        index = rng.choice(self.n_samples, size=n, replace=n > self.n_samples)
        return POSTERIOR_LAWS[self.law_name](**{name: v[index] for name, v in self.parameters.items()})

    def law_from_samples(self):
        """All samples as one law with (M,) parameters."""
        return POSTERIOR_LAWS[self.law_name](**self.parameters)


def with_shape_discrepancy(posterior: DampingPosterior, sigma: float, seed: int = 0) -> DampingPosterior:
    """The posterior with a law-shape discrepancy: each sample's Q(v) multiplied, at every velocity, by exp(e), e drawn
    from N(0, ``sigma``^2) (``sigma`` [-], the relative sd of Q).

    The laws are almost, not exactly, the plate's Q(v), by an amount the data cannot show (docs/damping.md, coverage
    over truths the fit does not contain): this widens every interval drawn from the posterior (the band of Q(v), the
    design's deflections and voltages) by that amount in quadrature, without moving its median.
    """
    if sigma <= 0:
        return posterior
    factor = np.exp(np.random.default_rng(seed).normal(0.0, sigma, posterior.n_samples))

    def scaled(law_name: str, parameters: dict) -> dict:
        """The law's parameters scaled, Q0 and alpha kept in their accepted ranges (a sample at a bound stays there)."""
        values = scaled_parameters(LAWS[law_name], parameters, factor)
        return {p: np.clip(v, *SCALED_RANGES[p]) if p in SCALED_RANGES else v for p, v in values.items()}

    if posterior.law_name != StackedLaws.name:
        return DampingPosterior(posterior.law_name, scaled(posterior.law_name, posterior.parameters), posterior.source)
    columns = dict(posterior.parameters)
    for name in STACKED_COMPONENTS:
        own = {p: columns[f"{name}_{p}"] for p in parameter_names(LAWS[name])}
        columns.update({f"{name}_{p}": v for p, v in scaled(name, own).items()})
    return DampingPosterior(posterior.law_name, columns, posterior.source)


NEUTRAL_PARAMETERS = {"q0": 1e3, "alpha": 0.0, "v_t": 1.0, "onset": 0.2, "v_top": 1.0, "v_first": 0.5}
"""Placeholder values (a constant Q of 1000; increments 0) for the columns of a law a stacked posterior does not mix."""


def stacked_posterior(posteriors: Dict[str, DampingPosterior], weights: Dict[str, float], n: int, seed: int = 0) -> DampingPosterior:
    """A model-averaged posterior: ``n`` draws, each from law k with probability ``weights[k]``.

    Parameters
    ----------
    posteriors : dict
        Law name -> its :class:`DampingPosterior` (names from
        :data:`~workflow.damping.laws.STACKED_COMPONENTS`).
    weights : dict
        Law name -> stacking weight [-] (normalised here).
    n : int
        Number of draws.
    seed : int
    """
    rng = np.random.default_rng(seed)
    names = [name for name in STACKED_COMPONENTS if name in posteriors]
    probability = np.array([max(weights.get(name, 0.0), 0.0) for name in names])
    component = rng.choice(len(names), size=n, p=probability / probability.sum())
    columns = {"component": np.array([STACKED_COMPONENTS.index(names[i]) for i in component], dtype=float)}
    for name in STACKED_COMPONENTS:
        own = posteriors.get(name)
        rows = None if own is None else rng.integers(len(next(iter(own.parameters.values()))), size=n)
        for p in parameter_names(LAWS[name]):
            # one posterior sample per draw for all of a law's parameters: their correlations are the posterior's
            columns[f"{name}_{p}"] = np.full(n, NEUTRAL_PARAMETERS.get(p, 0.0)) if own is None else own.parameters[p][rows]
    return DampingPosterior(StackedLaws.name, columns)


def save_posterior(posterior: DampingPosterior, path, sampled: np.ndarray, sampled_names) -> Path:
    """Write ``posterior`` (and the sampled coordinates, for reference) to ``path`` (.npz)."""
    path = Path(path)
    names = list(posterior.parameters)
    np.savez_compressed(
        path,
        law=np.array(posterior.law_name),
        parameter_names=np.array(names),
        parameter_samples=np.column_stack([posterior.parameters[name] for name in names]),
        sampled_names=np.array(list(sampled_names)),
        sampled=sampled,
    )
    return path


def load_posterior(path) -> DampingPosterior:
    """Read a posterior written by :func:`save_posterior` (a folder means its ``posterior.npz``).

    Raises
    ------
    InputFileError
        Missing or unreadable file, unknown law, or parameters that do not match the law.
    """
    path = Path(path)
    if path.is_dir():
        path = path / POSTERIOR_FILE
    if not path.exists():
        raise InputFileError(f"{path}: no such posterior file (write one with 'tactile fit-damping ... --out DIR')")
    try:
        with open_input(path, str(path), MAX_POSTERIOR_BYTES) as stream:
            content = np.load(stream, allow_pickle=False)
            if not isinstance(content, np.lib.npyio.NpzFile):
                raise ValueError("a single array, not an archive")
            unpacked = sum(info.file_size for info in content.zip.infolist())
            if unpacked > MAX_POSTERIOR_BYTES:
                raise InputFileError(f"{path}: unpacks to {unpacked} bytes, more than the {MAX_POSTERIOR_BYTES} accepted")
            law_name = str(content["law"])
            names = [str(name) for name in content["parameter_names"]]
            samples = np.asarray(content["parameter_samples"], dtype=float)
    except InputFileError:
        raise
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error):
        raise InputFileError(
            f"{path}: empty, truncated or not a posterior written by 'tactile fit-damping' "
            "(expected its posterior.npz or its --out folder)"
        ) from None
    if law_name not in POSTERIOR_LAWS:
        raise InputFileError(f"{path}: unknown Q(v) law {law_name!r}; expected one of {', '.join(POSTERIOR_LAWS)}")
    expected = list(parameter_names(POSTERIOR_LAWS[law_name]))
    if samples.ndim != 2 or samples.shape[1] != len(names) or len(samples) == 0:
        raise InputFileError(f"{path}: parameters {names} do not match the {law_name} law ({expected})")
    samples, names = _with_defaults(samples, names, law_name)
    if sorted(names) != sorted(expected):
        raise InputFileError(f"{path}: parameters {names} do not match the {law_name} law ({expected})")
    if not np.all(np.isfinite(samples)):
        raise InputFileError(f"{path}: non-finite posterior samples")
    ranges = {**SCALED_RANGES, "onset": ThresholdLoss.ONSET_RANGE, "component": (0, len(STACKED_COMPONENTS) - 1)}
    for i, name in enumerate(names):
        own = name.split("_", 1)[1] if law_name == StackedLaws.name and name != "component" else name
        low, high = ranges.get(own, (-np.inf, np.inf))
        if not np.all((samples[:, i] >= low) & (samples[:, i] <= high)):
            raise InputFileError(f"{path}: posterior samples of {name} outside the accepted range {low:g} to {high:g}")
    return DampingPosterior(law_name, {name: samples[:, i] for i, name in enumerate(names)}, source=str(path))


ADDED_PARAMETERS = {"onset": ThresholdLoss.onset}
"""Parameters added to a law after posterior files were written without them, and the value those files imply: the
threshold law's onset width was fixed at 0.2 of v_t before it was fitted (issue 29)."""


def _with_defaults(samples: np.ndarray, names: list, law_name: str) -> tuple:
    """``samples`` and ``names`` completed by the :data:`ADDED_PARAMETERS` a file of an earlier version lacks."""
    own = (lambda name: name.split("_", 1)[1]) if law_name == StackedLaws.name else (lambda name: name)
    missing = [name for name in parameter_names(POSTERIOR_LAWS[law_name]) if name not in names and own(name) in ADDED_PARAMETERS]
    columns = [np.full((len(samples), 1), ADDED_PARAMETERS[own(name)]) for name in missing]
    return np.hstack([samples, *columns]), names + missing
