

def in_reference_basis(oracle, rgba, rgb_to_xyz):
    """A spectral effect's float64 oracle in another working space: ``rgba`` carried into the
    reference basis (linear Rec.709) by ``B = XYZ_TO_REC709 @ rgb_to_xyz``, the Rec.709
    oracle ``oracle(rgba_ref)``, and its output carried back by ``B^-1`` (alpha kept), as
    clfx.kit.spectral.in_reference_basis does on the device."""
    import numpy as np

    from clfx.core.colour import XYZ_TO_REC709

    b = XYZ_TO_REC709 @ np.asarray(rgb_to_xyz, np.float64)
    src = np.array(rgba, np.float64)
    src[..., :3] = src[..., :3] @ b.T
    out = np.array(oracle(src), np.float64)
    out[..., :3] = out[..., :3] @ np.linalg.inv(b).T
    return out
