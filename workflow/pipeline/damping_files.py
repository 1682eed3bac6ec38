"""Files of a damping fit: the posterior samples (what ``--damping`` loads), ``fit.json`` and figures."""

import json
from pathlib import Path

from workflow.damping.fit import fit_summary
from workflow.damping.posterior import POSTERIOR_FILE, save_posterior
from workflow.errors import InputFileError
from workflow.pipeline.outputs import writable_folder
from workflow.serialise import jsonable

FIT_OUTPUTS = ("posterior*.npz", "fit.json", "*.png")
"""Glob patterns of the files a fit writes into its folder (:mod:`workflow.pipeline.outputs`)."""


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
        {"posterior": path of posterior.npz, "figures": [paths]}.
    """
    out = writable_folder(out)
    outputs = {POSTERIOR_FILE: fit.best, **{f"posterior_{name}.npz": law_fit for name, law_fit in fit.fits.items()}}
    for name, law_fit in outputs.items():
        _refuse_overwriting_input(out / name, protect)
        save_posterior(law_fit.posterior(), out / name, law_fit.samples, law_fit.data.layout.names)
    files = {"posterior": str(out / POSTERIOR_FILE), "figures": _write_figures(fit, out, protect) if figures else []}
    _refuse_overwriting_input(out / "fit.json", protect)
    (out / "fit.json").write_text(json.dumps(dict(fit_summary(fit), files=files), indent=2, default=jsonable) + "\n")
    return files


def _write_figures(fit, out: Path, input_paths) -> list:
    import matplotlib.pyplot as plt

    from workflow.pipeline.figures.damping import fit_figures

    written = []
    for name, figure in fit_figures(fit).items():
        _refuse_overwriting_input(out / name, input_paths)
        figure.savefig(out / name, dpi=120)
        plt.close(figure)
        written.append(str(out / name))
    return written


def _refuse_overwriting_input(path: Path, input_paths) -> None:
    if path.resolve() in input_paths:
        raise InputFileError(f"--out: writing {path} would overwrite an input log; choose another folder")


