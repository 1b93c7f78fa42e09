"""One bench case module per effect: ``clfx/bench/cases/<effect>.py`` defines ``CASE``.

A case is what ``clfx bench`` measures an effect on (its representative hard case), the
peers doing the same operation (OpenCV, SciPy), the naive method every level must beat,
and, for effects whose levels draw different random samples, the statistics to compare
instead of pixels.  Effect modules know nothing of the bench: everything here may import
scenes, ground truth, OpenCV and SciPy, which no plugin may.

``CASE = Case(make, peers=None, metrics=None, naive=None, variants={})``:

``make(width, height, rng) -> dict`` returns:

- ``source`` (h, w, 4) float32, and optionally ``depth`` (h, w), ``velocity`` (h, w, 2),
  ``data_window``, ``display_window``, ``pixel_aspect``, ``frame``, ``seed``, ``camera``,
  ``display_referred``;
- ``params``: the effect's parameters for the case;
- ``truth``: a multisample ground truth, when the reference is not the effect's own
  ``reference`` level (cases with a truth are cached on disk, keyed by their sources);
- ``edge_mask``: where the edge-band error is measured (else derived from depth/velocity).

``peers(case, params, ctx) -> {label: fn | (fn, level)}``: host callables returning RGBA,
compared with the clfx ``level`` doing the same work (``final`` when not given).

``naive``: ``Naive(label, make)``, the plain method the effect exists to beat (a per-pixel
CoC gather for depth of field, a per-pixel line blur for motion blur, bilinear remap on the
exact map for distortion).  ``make(case, params, ctx)`` returns a callable ``fn()`` giving
RGBA (h, w, 4) over the case's source window (a host function; a device method downloads
its result, ``rt.download``, before returning).  ``case`` is ``make``'s dict, ``params`` the
effect's parsed parameters, ``ctx`` a ``clfx.host.RenderContext`` of the case at ``final``
(``ctx.runtime`` for device work).  The runner times it like a level and scores it against
the same reference.  Example::

    def per_pixel_gather(case, params, ctx):
        coc = ...                                  # host work done once, outside the timing
        return lambda: gather(case["source"], coc)

    CASE = Case(make=make, naive=Naive("per-pixel CoC gather", per_pixel_gather))

Beside every quality level the runner always reports the naive method's row (when declared)
and the unchanged input's row (``source`` itself), each with log-PSNR and edge-band RMSE
against the same reference, and flags each level ``beats naive`` / ``beats input`` (higher
log-PSNR: "yes" or "NO") in the JSON, the markdown tables and the summary.

``variants``: ``{name: make}``, more cases of the same effect (other scene classes), each
with ``make``'s signature; ``clfx bench`` measures each like the main case, under the name
``<effect>:<name>``, with the same peers, naive method and metrics.

``metrics(out, ref, case) -> dict``: replaces the pixel error metrics (noise effects, whose
levels draw different samples): the runner scores every level, the naive method, the
unchanged input and every peer with it, against the same ``ref``.  The dict holds at least
``rmse``, ``max_err``, ``rel_rmse`` and ``psnr_log`` (the tables print them; ``beats naive``
/ ``beats input`` compare ``psnr_log``, higher is better), e.g. ``grain``'s statistics PSNR.

A module whose truth is computed with code outside ``clfx.bench.scene`` and
``clfx.bench.groundtruth`` lists those modules in ``TRUTH_DEPENDS`` (names), so that the
cached truth is rebuilt when they change.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from types import ModuleType
from typing import Callable, Mapping


@dataclass(frozen=True)
class Naive:
    """The naive method of a case: ``label`` (what it is, in a few words) and
    ``make(case, params, ctx) -> fn``, ``fn()`` returning RGBA over the source window."""

    label: str
    make: Callable[..., Callable[[], object]]


@dataclass(frozen=True)
class Case:
    make: Callable[..., dict]
    peers: Callable[..., dict] | None = None
    metrics: Callable[..., dict] | None = None
    naive: Naive | None = None
    variants: Mapping[str, Callable[..., dict]] = field(default_factory=dict)

    def maker(self, variant: str | None = None) -> Callable[..., dict]:
        """``make`` of the main case (``variant`` None) or of a named variant."""
        if variant is None:
            return self.make
        try:
            return self.variants[variant]
        except KeyError:
            raise KeyError(f"no bench variant {variant!r} (have: {', '.join(self.variants) or 'none'})") from None


def module_for(effect: str) -> ModuleType | None:
    """The case module of ``effect``, or None when it has none."""
    try:
        return importlib.import_module(f"{__name__}.{effect}")
    except ModuleNotFoundError as exc:
        if exc.name != f"{__name__}.{effect}":
            raise
        return None


def for_effect(effect: str) -> Case | None:
    """The declared bench case of ``effect`` (its module's ``CASE``), or None."""
    module = module_for(effect)
    return None if module is None else module.CASE
