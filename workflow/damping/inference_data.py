"""A law's posterior as ArviZ InferenceData, for PSIS-LOO and standard tools (``posterior.nc``).

Groups: ``posterior`` (every sampled coordinate in natural units: ``q0``, ``alpha``, ...,
``gain`` [m/V], ``f_r_<k>`` [Hz], ``sigma_rel``, ``sigma_abs`` [m/s]; emcee's walkers as
chains), ``sample_stats`` (``lp``: the log-posterior), ``log_likelihood`` (``velocity``: ln p
of each measured row), ``observed_data`` (``velocity`` [m/s]) and ``constant_data``
(``frequency`` [Hz], ``voltage`` [V], ``sweep``).  At most :data:`MAX_DRAWS` draws are kept
(the chain thinned further), which is what LOO and the checks use.
"""

import warnings
from pathlib import Path

import arviz as az
import numpy as np

from workflow.damping.likelihood import FitData, pointwise_log_likelihood
from workflow.errors import InputFileError

MAX_DRAWS = 2000
"""Largest number of posterior draws (walkers x steps) kept in the InferenceData [-]."""


def loo_draws(chain: np.ndarray, log_prob: np.ndarray, data: FitData):
    """At most :data:`MAX_DRAWS` draws of a chain and their pointwise log-likelihood, as plain arrays.

    Parameters
    ----------
    chain : numpy.ndarray (S, W, D)
        Post-burn-in, thinned samples in the sampled coordinates (emcee's ``get_chain``).
    log_prob : numpy.ndarray (S, W)
        Their log-posterior.
    data : FitData

    Returns
    -------
    (chain (S', W, D), log_prob (S', W), pointwise (S', W, N))
    """
    n_steps, n_walkers, _ = chain.shape
    keep = np.unique(np.linspace(0, n_steps - 1, max(1, min(n_steps, MAX_DRAWS // n_walkers))).astype(int))
    chain, log_prob = chain[keep], log_prob[keep]
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):  # as the chain's own log-probability: the
        # softened solve's root search may overflow on its way for a draw at the edge of the posterior
        pointwise = pointwise_log_likelihood(chain.reshape(-1, chain.shape[-1]), data).reshape(len(keep), n_walkers, -1)
    return chain, log_prob, pointwise


def law_inference_data(chain: np.ndarray, log_prob: np.ndarray, pointwise: np.ndarray, data: FitData) -> az.InferenceData:
    """InferenceData of one law's draws (the arrays of :func:`loo_draws`)."""
    n_steps, n_walkers, _ = chain.shape
    natural = data.layout.natural(chain.reshape(-1, chain.shape[-1]))
    with warnings.catch_warnings():  # walkers are the chains: often more of them than thinned draws, which is right
        warnings.filterwarnings("ignore", message=r"More chains \(\d+\) than draws", category=UserWarning)
        return _from_dict(natural, n_steps, n_walkers, log_prob, pointwise, data)


def _from_dict(natural: dict, n_steps: int, n_walkers: int, log_prob, pointwise, data: FitData) -> az.InferenceData:
    return az.from_dict(
        posterior={name: values.reshape(n_steps, n_walkers).T for name, values in natural.items()},
        sample_stats={"lp": log_prob.T},
        log_likelihood={"velocity": np.transpose(pointwise, (1, 0, 2))},
        observed_data={"velocity": data.velocity},
        constant_data={"frequency": data.frequency, "voltage": data.voltage, "sweep": data.sweep},
        dims={"velocity": ["row"], "frequency": ["row"], "voltage": ["row"], "sweep": ["row"]},
        attrs={"law": data.layout.law_name, **{name: value for name, value in data.layout.fixed}},
    )


def save_inference_data(idata: az.InferenceData, path) -> Path:
    """Write ``idata`` to ``path`` (netCDF)."""
    path = Path(path)
    idata.to_netcdf(str(path))
    return path


def load_inference_data(path) -> az.InferenceData:
    """Read a ``posterior.nc`` written by :func:`save_inference_data`.

    Raises
    ------
    InputFileError
        Missing or not a netCDF InferenceData with a log-likelihood.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{path}: no such InferenceData file (written by 'tactile fit-damping ... --out DIR')")
    try:
        idata = az.from_netcdf(str(path))
    except (OSError, ValueError):
        raise InputFileError(f"{path}: not a netCDF InferenceData file") from None
    if "log_likelihood" not in idata.groups():
        raise InputFileError(f"{path}: no log_likelihood group (not written by 'tactile fit-damping')")
    return idata
