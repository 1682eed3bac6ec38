"""The Q(v) posterior as a file: what ``tactile fit-damping`` writes and ``--damping`` reads.

``posterior.npz`` (numpy, no pickles) holds the law's name, its parameters' posterior
samples in natural units (``q0`` [-], ``alpha`` [s^2/m^2 or s/m]), and the full sampled
coordinates for reference.
"""

import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Dict

import numpy as np

from workflow.damping.laws import LAWS, parameter_names
from workflow.damping.likelihood import Q0_RANGE
from workflow.errors import InputFileError

POSTERIOR_FILE = "posterior.npz"
"""File name of the posterior in a fit's output folder."""
MAX_ALPHA = 1e12
"""Largest accepted loss coefficient alpha [s^2/m^2 or s/m]: the fit's prior bound for the quadratic law
at the smallest peak velocity a log may have (1e-6 m/s)."""


@dataclass(frozen=True)
class DampingPosterior:
    """Posterior samples of a Q(v) law's parameters.

    Attributes
    ----------
    law_name : str
        A key of :data:`~workflow.damping.laws.LAWS`.
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

    def median_law(self):
        """The law at the marginal posterior medians of its parameters."""
        return LAWS[self.law_name](**{name: float(np.median(v)) for name, v in self.parameters.items()})

    def draws(self, n: int, seed: int = 0):
        """``n`` posterior draws (without replacement when possible) as one law with (n,) parameters."""
        rng = np.random.default_rng(seed)
        index = rng.choice(self.n_samples, size=n, replace=n > self.n_samples)
        return LAWS[self.law_name](**{name: v[index] for name, v in self.parameters.items()})

    def law_from_samples(self):
        """All samples as one law with (M,) parameters."""
        return LAWS[self.law_name](**self.parameters)


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
    try:
        with np.load(path, allow_pickle=False) as content:
            law_name = str(content["law"])
            names = [str(name) for name in content["parameter_names"]]
            samples = np.asarray(content["parameter_samples"], dtype=float)
    except FileNotFoundError:
        raise InputFileError(f"{path}: no such posterior file (write one with 'tactile fit-damping ... --out DIR')") from None
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error):
        raise InputFileError(
            f"{path}: empty, truncated or not a posterior written by 'tactile fit-damping' "
            "(expected its posterior.npz or its --out folder)"
        ) from None
    if law_name not in LAWS:
        raise InputFileError(f"{path}: unknown Q(v) law {law_name!r}; expected one of {', '.join(LAWS)}")
    expected = list(parameter_names(LAWS[law_name]))
    if sorted(names) != sorted(expected) or samples.ndim != 2 or samples.shape[1] != len(names) or len(samples) == 0:
        raise InputFileError(f"{path}: parameters {names} do not match the {law_name} law ({expected})")
    if not np.all(np.isfinite(samples)):
        raise InputFileError(f"{path}: non-finite posterior samples")
    ranges = {"q0": Q0_RANGE, "alpha": (0.0, MAX_ALPHA)}
    for i, name in enumerate(names):
        low, high = ranges.get(name, (-np.inf, np.inf))
        if not np.all((samples[:, i] >= low) & (samples[:, i] <= high)):
            raise InputFileError(f"{path}: posterior samples of {name} outside the accepted range {low:g} to {high:g}")
    return DampingPosterior(law_name, {name: samples[:, i] for i, name in enumerate(names)}, source=str(path))
