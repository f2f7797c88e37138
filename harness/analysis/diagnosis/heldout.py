"""Which samples fit the shared effect parameters and which are held out (the user's choice, then one rule).

A *held-out sample* never informs the shared effect parameters (one coil, one filler, one matrix material,
...): they are fitted on the *shared-fit samples*, then each held-out sample gets only its own base
parameters fitted to its own fit tests, with the effect parameters fixed. Its held-out-test RMSE thus
shows whether the effect transfers to a sample the effect fit never saw.

The choice depends on the dataset and on what the user declared, never on the virtual rig's sample names:

1. Samples the user declared unseen (``DiagnoseSettings.unseen``; ``mpc-actuator diagnose --unseen ID ...``)
   are always held-out samples. Unknown ids are an error naming them (:class:`UnseenSampleError`), and
   so is declaring every sample unseen (nothing would be left to fit the effect parameters on).
2. The shared-fit samples are picked from the remaining samples by one rule (:func:`shared_fit_samples`):
   sort them by (diameter, filler fraction, id) and take ``k = min(max_shared_samples, n_remaining)``
   evenly spaced ones (first and last included), so that the effect parameters are fitted across the
   range of geometry and composition. When the user declared none and the dataset has at least
   ``min_samples_holdout`` samples, ``k`` is at most n - 1: at least one sample is always held out.
3. Every other sample is a held-out sample as well.

Why not leave-one-out over the samples: every fold costs a whole candidate round (all candidates
refitted), i.e. ~n times the diagnosis; the rule above costs nothing extra and still tests the transfer on
every sample outside the shared fit. Why at most ``max_shared_samples`` (4) in the shared fit: the joint
fit's cost grows with the number of samples in it, and a shared physical constant is pinned down by a
few samples spread over the geometry.
"""
from __future__ import annotations

RULE = ("samples declared unseen (--unseen) are held out; the shared effect parameters are fitted on up to "
        "max_shared_samples of the other samples, evenly spaced in (diameter, filler fraction, id) order with the "
        "first and last included (at least one sample held out from min_samples_holdout samples on when none is "
        "declared); every sample outside the shared fit is a held-out sample")


class UnseenSampleError(ValueError):
    """Samples declared unseen that the dataset does not have, or every sample declared unseen."""


def declared_unseen(sample_ids, unseen) -> tuple:
    """The declared-unseen ids in dataset order (``unseen``: ids or None); raises :class:`UnseenSampleError`.

    Parameters
    ----------
    sample_ids : sequence of str
        The dataset's sample ids, in order.
    unseen : iterable of str or None
        Ids the user declared unseen (None or empty: none).

    Returns
    -------
    tuple of str
    """
    ids = [str(s) for s in sample_ids]
    want = [str(u) for u in (unseen or ())]
    unknown = [u for u in want if u not in ids]
    if unknown:
        raise UnseenSampleError(f"sample(s) {', '.join(unknown)} declared unseen (--unseen) but not in the dataset "
                                f"(its samples: {', '.join(ids) or 'none'})")
    out = tuple(i for i in ids if i in set(want))
    if ids and len(out) == len(ids):
        raise UnseenSampleError(f"every sample ({', '.join(ids)}) is declared unseen (--unseen): at least one must "
                                "remain to fit the shared effect parameters")
    return out


def shared_fit_samples(samples, settings) -> list:
    """Indices of the shared-fit samples (the rule in the module docstring).

    Parameters
    ----------
    samples : sequence
        Prepared samples with ``sid``, ``diameter_mm`` [mm], ``wt_pct`` [wt%] and ``unseen`` (declared unseen).
    settings : DiagnoseSettings
        ``max_shared_samples`` and ``min_samples_holdout``.

    Returns
    -------
    list of int
        Sorted indices into ``samples``.
    """
    pool = [i for i, s in enumerate(samples) if not s.unseen]
    if not pool:
        raise UnseenSampleError("every sample is declared unseen: at least one must remain for the shared fit")
    k = max(1, min(settings.max_shared_samples, len(pool)))
    if len(samples) >= settings.min_samples_holdout and k == len(samples):
        k = len(samples) - 1          # nothing declared: keep at least one held-out sample
    order = sorted(pool, key=lambda i: (float(samples[i].diameter_mm), float(samples[i].wt_pct), str(samples[i].sid)))
    if k > 1:
        pick = [order[int(round(q * (len(order) - 1) / (k - 1)))] for q in range(k)]
    else:
        pick = [order[len(order) // 2]]
    return sorted(set(pick))
