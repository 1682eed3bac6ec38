"""Files of a damping fit: the posterior samples (what ``--damping`` loads), ``fit.json`` and figures."""

import json
import shutil
from pathlib import Path

from workflow import logformat
from workflow.damping.fit import fit_summary
from workflow.damping.inference_data import save_inference_data
from workflow.damping.posterior import POSTERIOR_FILE, save_posterior
from workflow.errors import InputFileError
from workflow.models.limits import problem
from workflow.pipeline.outputs import save_figure, writable_folder
from workflow.serialise import jsonable

FIT_OUTPUTS = ("posterior*.npz", "posterior*.nc", "fit.json", "*.png")
"""Glob patterns of the files a fit writes into its folder (:mod:`workflow.pipeline.outputs`)."""
INFERENCE_DATA_FILE = "posterior.nc"
"""ArviZ InferenceData (netCDF) of the preferred law, next to ``posterior.npz``."""
STATED_NOISE_KEYS = ("velocity_noise_relative", "simulator_relative_noise")
"""Log metadata keys giving the vibrometer's relative velocity noise [-] (a real bench's, then the simulator's)."""


def stated_noise(paths):
    """The instrument's relative velocity noise [-] stated in the logs' metadata, or None.

    Reads the leading ``# key: value`` lines of each log (docs/log-format.md) for
    :data:`STATED_NOISE_KEYS`; the largest stated value over the logs is returned.
    """
    values = []
    for path in paths:
        metadata = logformat.read_metadata(path)
        for key in (key for key in STATED_NOISE_KEYS if key in metadata):
            value = logformat.metadata_number(metadata, key, path)
            reason = problem("simulator.relative_noise", value, name=key)
            if reason:
                raise InputFileError(f"{path}, line {metadata[key][1]}: {reason}")
            values.append(value)
    return max(values) if values else None


def write_fit(fit, out, figures: bool = True, protect=()) -> dict:
    """Write a fit's posterior files, ``fit.json`` and (optionally) its figures into ``out``.

    Parameters
    ----------
    fit : DampingFit
    out : path-like
        Folder, created if missing.
    figures : bool
    protect : collection of Path
        Resolved paths that must not be overwritten (the input logs).

    Returns
    -------
    dict
        {"posterior": path of posterior.npz (the answer the design uses), "inference_data":
        path of posterior.nc (the preferred law), "figures": [paths]}.
    """
    out = writable_folder(out)
    for name, law_fit in fit.fits.items():
        _refuse_overwriting_input(out / f"posterior_{name}.npz", protect)
        save_posterior(law_fit.posterior(), out / f"posterior_{name}.npz", law_fit.samples, law_fit.data.layout.names)
        _refuse_overwriting_input(out / f"posterior_{name}.nc", protect)
        save_inference_data(law_fit.inference_data, out / f"posterior_{name}.nc")
    _refuse_overwriting_input(out / POSTERIOR_FILE, protect)
    answer_fit = fit.fits.get(fit.answer.law_name)
    sampled = (answer_fit.samples, answer_fit.data.layout.names) if answer_fit else (fit.best.samples, fit.best.data.layout.names)
    save_posterior(fit.answer, out / POSTERIOR_FILE, *sampled)
    _refuse_overwriting_input(out / INFERENCE_DATA_FILE, protect)
    shutil.copyfile(out / f"posterior_{fit.preferred}.nc", out / INFERENCE_DATA_FILE)  # the preferred law's, written above
    files = {
        "posterior": str(out / POSTERIOR_FILE),
        "inference_data": str(out / INFERENCE_DATA_FILE),
        "figures": _write_figures(fit, out, protect) if figures else [],
    }
    _refuse_overwriting_input(out / "fit.json", protect)
    (out / "fit.json").write_text(json.dumps(dict(fit_summary(fit), files=files), indent=2, default=jsonable) + "\n")
    return files


def _write_figures(fit, out: Path, input_paths) -> list:
    from workflow.pipeline.figures.damping import fit_figures

    written = []
    for name, (_, draw) in fit_figures(fit).items():
        _refuse_overwriting_input(out / name, input_paths)
        written.append(save_figure(draw(), out / name))
    return written


def _refuse_overwriting_input(path: Path, input_paths) -> None:
    if path.resolve() in input_paths:
        raise InputFileError(f"--out: writing {path} would overwrite an input log; choose another folder")


