"""How well an envelope follows the wanted one: RMS error, rise and fall times, contrast per period.

The envelope error is the RMS difference between achieved and wanted envelopes over the
texture's swing (its highest minus its lowest level; its mean level for a flat texture): 10 %
means a deviation of a tenth of the contrast the texture asks for.  Rise and fall times are
the 10-90 % times of the achieved envelope after each step of the wanted one (a change of more
than half its swing between neighbouring samples), interpolated between samples.
"""

import numpy as np

STEP_SHARE = 0.5
"""A change of the wanted envelope by more than this share of its swing between samples is a step [-]."""


def envelope_error(achieved, wanted, axis=-1):
    """RMS(achieved - wanted) over the swing of ``wanted`` (max - min; its mean when flat) [-], along ``axis``."""
    achieved, wanted = np.broadcast_arrays(np.asarray(achieved, dtype=float), np.asarray(wanted, dtype=float))
    rms = np.sqrt(np.mean(np.square(achieved - wanted), axis=axis))
    span = np.max(wanted, axis=axis) - np.min(wanted, axis=axis)
    return rms / np.where(span > 0, span, np.mean(np.abs(wanted), axis=axis))


def _crossing(time, values, level, rising: bool):
    """First time ``values`` crosses ``level`` in the given direction, linear between samples; None if never."""
    above = values >= level if rising else values <= level
    if not np.any(above):
        return None
    index = int(np.argmax(above))
    if index == 0:
        return float(time[0])
    t0, t1, v0, v1 = time[index - 1], time[index], values[index - 1], values[index]
    return float(t0 + (level - v0) / (v1 - v0) * (t1 - t0)) if v1 != v0 else float(t1)


def transition_times(time, achieved, wanted) -> dict:
    """10-90 % rise and fall times of ``achieved`` after each step of ``wanted`` [s].

    Returns
    -------
    dict
        ``rise`` and ``fall``: lists with one time per step [s], None where the achieved envelope did not
        cross 90 % of the step before the next one.
    """
    time, achieved, wanted = (np.asarray(x, dtype=float) for x in (time, achieved, wanted))
    steps = np.nonzero(np.abs(np.diff(wanted)) > STEP_SHARE * np.ptp(wanted))[0] + 1
    bounds = list(steps) + [len(wanted)]
    result = {"rise": [], "fall": []}
    for start, stop in zip(steps, bounds[1:]):
        before, after = wanted[start - 1], wanted[start]
        rising = after > before
        segment = slice(start - 1, stop)
        first = _crossing(time[segment], achieved[segment], before + 0.1 * (after - before), rising)
        last = _crossing(time[segment], achieved[segment], before + 0.9 * (after - before), rising)
        duration = None if first is None or last is None else last - first
        result["rise" if rising else "fall"].append(duration)
    return result


def contrast_per_period(time, envelope, period) -> list:
    """Michelson contrast (max - min) / (max + min) of ``envelope`` in each whole ``period`` [s] of ``time`` [-]."""
    time, envelope = np.asarray(time, dtype=float), np.asarray(envelope, dtype=float)
    contrasts = []
    for k in range(int(np.floor((time[-1] - time[0]) / period + 1e-9))):
        inside = (time >= time[0] + k * period) & (time < time[0] + (k + 1) * period)
        high, low = np.max(envelope[inside]), np.min(envelope[inside])
        contrasts.append(float((high - low) / (high + low)) if high + low > 0 else 0.0)
    return contrasts


def median_time(times):
    """Median of the times that are not None [s], or None."""
    known = [t for t in times if t is not None]
    return float(np.median(known)) if known else None
