"""Identity: an effect says why it has nothing to do, and then changes nothing.

The neutral settings are found from each descriptor (``effects.neutral_candidates``: each
numeric parameter set to 0 where its range allows, each switch turned off, then all of them
at once).  For every candidate, ``is_identity`` gives a non-empty reason exactly when
rendering anyway leaves the frame unchanged; at least one candidate is an identity, and then
its render (`tests.effects.render_effect`) returns the input bit for bit.  The active
parameters of the other contract tests are no identity (so those tests render).
"""
import numpy as np
import pytest

from tests.contract import effects as E
from tests.contract.known import param


@pytest.mark.parametrize("name", [param("test_identity_has_a_reason_and_changes_nothing",
                                        n, id=n) for n in E.EFFECTS])
def test_identity_has_a_reason_and_changes_nothing(rt, name):
    src = E.scene()
    plugin = E.plugin(name)
    assert plugin.is_identity(E.params(name), E.context(rt, name, src)) is None, \
        f"{name}: the contract's active parameters {E.ACTIVE.get(name, {})} do nothing"
    identities = []
    for change in E.neutral_candidates(name):
        p = E.params(name, **change)
        reason = plugin.is_identity(p, E.context(rt, name, src))
        rendered = plugin.render(rt, p, E.context(rt, name, src)).download()
        # unchanged up to float32 rounding (a resampler at zero shift, weights summing to 1)
        no_op = rendered.shape == src.shape and np.allclose(rendered, src, rtol=1e-5, atol=1e-5)
        assert bool(reason) == no_op, (
            f"{name} with {change}: is_identity says {reason!r} but rendering "
            f"{'changes nothing' if no_op else 'changes the frame'}")
        if reason:
            assert isinstance(reason, str) and reason.strip(), (name, change, reason)
            out = E.apply(rt, name, src, p)
            assert out.tobytes() == src.tobytes(), f"{name} with {change}: {reason!r} but " \
                                                   f"apply() changed the frame"
            identities.append(change)
    assert identities, f"{name}: no neutral setting among {E.neutral_candidates(name)}"
