"""float64 sequential ray tracer: the oracle of the paraxial ghosts in clfx/fx/optics.py.

Exact spherical surfaces, vector Snell's law, the stop and every clear aperture vignetting
each ray at each crossing, and reflections at the two ghost surfaces.  A distant point light
at ``field_deg`` off the axis (in the x-z plane) sends a parallel beam; rays start on a
regular grid over the first surface's clear aperture, in two stages (a coarse grid finds the
part of the beam that survives the path, a fine grid over its bounding box measures it), and
land on the image plane (the last surface's thickness behind it).

Fresnel factors come from the general thin-film (Airy) formula with s and p averaged
(unpolarised light; a stack of films film by film), written here independently of ``clfx.fx.optics``: ``fresnel="normal"``
evaluates it at normal incidence (the matrix model's assumption, so the comparison isolates
geometry), ``fresnel="exact"`` at each ray's incidence angle (the physics the paraxial model
leaves out).  Only the prescription's data (radii, thicknesses, semi-apertures, coatings and
its dispersion formula ``media``) is shared with the code under test.

A ghost of a real lens can have more than one part: far from the axis, aberrations can
steer a zone of the beam through the stop by a route the paraxial rays do not take (a ring
or crescent that the paraxial model cannot know).  The spot measured is the part whose rays
enter the lens nearest the axis, the paraxial zone: the connected region (8-connected, on
the coarse grid and again on the fine one) of surviving entrance points that holds the one
closest to the axis.  The other parts' power is reported separately (``other_power_mm2``).

A spot is summarised by the power-weighted centroid of the landed rays, its radius
``sqrt(2) * rms distance`` from the centroid (exactly the edge radius of a uniformly filled
disc, and robust to the few rays a caustic throws far out), its extent (the largest
distance) and its power relative to the light entering the entrance pupil (the area of the
entrance beam that survives the primary path).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

START_BACK_MM = 1000.0   # rays start this far before the first vertex plane


@dataclass(frozen=True)
class Spot:
    n_rays: int
    area_mm2: float          # entrance-beam area (perpendicular to the axis) that lands
    power_mm2: float         # the same, weighted by each ray's Fresnel factors
    centroid: tuple          # (x, y) on the image plane, mm
    radius_mm: float         # sqrt(2) * rms distance from the centroid
    extent_mm: float         # largest distance from the centroid
    other_power_mm2: float = 0.0   # power of the parts not connected to the paraxial zone


def _r_interface(na, ca, nb, cb):
    """Amplitude reflection (s, p) from medium a into b, cosines ca, cb (complex)."""
    rs = (na * ca - nb * cb) / (na * ca + nb * cb)
    rp = (nb * ca - na * cb) / (nb * ca + na * cb)
    return rs, rp


def reflectance(n1, n2, cos1, coating, wavelength_nm):
    """Unpolarised reflectance of a bare or coated interface at incidence cosine ``cos1``
    (from medium ``n1``); Born & Wolf sec. 1.5.2 and 1.6.4.  A stack of films (``coating.
    layers``, from the lower-index side, each ``(index, quarter waves of coating.
    wavelength_nm)``) by Airy's formula applied film by film from the far side (the
    recursion of Rouard's method), not by characteristic matrices as the code under test."""
    cos1 = np.asarray(cos1, np.complex128)
    sin2 = 1.0 - cos1 * cos1
    cos2 = np.sqrt(1.0 - (n1 / n2) ** 2 * sin2 + 0j)
    if coating is None:
        rs, rp = _r_interface(n1, cos1, n2, cos2)
        return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)
    films = list(getattr(coating, "layers", ()) or ((coating.index, 1.0),))
    if n1 > n2:                          # arriving from the glass: the films in reverse
        films = films[::-1]
    idx = [n1] + [f[0] for f in films] + [n2]
    cos = [np.sqrt(1.0 - (n1 / n) ** 2 * sin2 + 0j) for n in idx]
    out = []
    for pol in (0, 1):
        r = _r_interface(idx[-2], cos[-2], idx[-1], cos[-1])[pol]
        for k in range(len(films) - 1, -1, -1):        # film k lies between idx[k], idx[k+2]
            nf, qw = films[k]
            thickness = qw * coating.wavelength_nm / (4.0 * nf)
            phase = np.exp(2j * (2.0 * np.pi * nf * thickness * cos[k + 1] / wavelength_nm))
            r0 = _r_interface(idx[k], cos[k], nf, cos[k + 1])[pol]
            r = (r0 + r * phase) / (1.0 + r0 * r * phase)
        out.append(r)
    return 0.5 * (np.abs(out[0]) ** 2 + np.abs(out[1]) ** 2)


def ghost_path(lens, i, j):
    """[(surface, action)]: forward to ``i``, reflect, back to ``j``, reflect, forward."""
    n = len(lens.surfaces)
    return ([(k, "fwd") for k in range(i)] + [(i, "reflect")]
            + [(k, "back") for k in range(i - 1, j, -1)] + [(j, "reflect")]
            + [(k, "fwd") for k in range(j + 1, n)])


def primary_path(lens):
    return [(k, "fwd") for k in range(len(lens.surfaces))]


def _trace(lens, path, p0, direction, wavelength_nm, fresnel):
    """Trace rays starting at entrance-plane points ``p0`` (M, 2); return landed (x, y) and
    weights (NaN and 0 for lost rays), and the mask of surviving rays."""
    with np.errstate(all="ignore"):   # a ray lost this crossing may run to inf/nan
        return _trace_rays(lens, path, p0, direction, wavelength_nm, fresnel)


def _trace_rays(lens, path, p0, direction, wavelength_nm, fresnel):
    """The rays as separate x, y, z arrays; a ray lost at a crossing (outside a clear
    aperture, missing a sphere, reflected totally) is dropped from them there, so each
    crossing computes only the rays still alive (``idx`` says which they are).  Dot products
    add x, z, then y: the order NumPy's ``einsum("ij,ij->i")`` over (M, 3) arrays takes, so
    every ray lands bit for bit where the former (M, 3) version of this tracer put it."""
    s = lens.surfaces
    n = lens.media(wavelength_nm)[:, 0]
    z_vertex = np.concatenate([[0.0], np.cumsum([x.thickness for x in s])])
    m = len(p0)
    idx = np.arange(m)
    dx = np.full(m, float(direction[0]))
    dy = np.full(m, float(direction[1]))
    dz = np.full(m, float(direction[2]))
    ox = p0[:, 0] - START_BACK_MM * dx
    oy = p0[:, 1] - START_BACK_MM * dy
    oz = 0.0 - START_BACK_MM * dz
    # with Fresnel at normal incidence every ray carries the same factors: one number
    weight = np.ones(m) if fresnel == "exact" else np.float64(1.0)
    going_forward = True
    for k, action in path:
        surf = s[k]
        zk = z_vertex[k]
        if np.isinf(surf.radius):
            t = (zk - oz) / dz
            nx = ny = 0.0
            nz = -1.0
            ok = np.isfinite(t) & (t > 1e-9)
            hx, hy, hz = ox + t * dx, oy + t * dy, oz + t * dz
        else:
            r = surf.radius
            cz = zk + r
            ocz = oz - cz
            b = (dx * ox + dz * ocz) + dy * oy
            c = ((ox * ox + ocz * ocz) + oy * oy) - r * r
            disc = b * b - c
            root = np.sqrt(np.maximum(disc, 0.0))
            hits = disc >= 0.0
            t = np.inf                   # the nearer root ahead on the vertex's hemisphere
            for t_try in (-b - root, -b + root):
                good = hits & (t_try > 1e-9) & (((oz + t_try * dz) - cz) * r < 0.0)
                t = np.where(good & (t_try < t), t_try, t)
            ok = np.isfinite(t)
            t[~ok] = 0.0
            hx, hy, hz = ox + t * dx, oy + t * dy, oz + t * dz
            nx, ny, nz = hx / r, hy / r, (hz - cz) / r      # unit; -z at the vertex
        ok &= hx * hx + hy * hy <= surf.semi_aperture ** 2
        dn = (dx * nx + dz * nz) + dy * ny
        if action == "reflect":
            n1, n2 = (n[k], n[k + 1]) if going_forward else (n[k + 1], n[k])
            if fresnel == "exact":
                weight = weight * reflectance(n1, n2, np.abs(dn), surf.coating, wavelength_nm)
            else:
                weight = weight * reflectance(n1, n2, 1.0, surf.coating, wavelength_nm)
            two = 2.0 * dn
            dx, dy, dz = dx - two * nx, dy - two * ny, dz - two * nz
            going_forward = not going_forward
        else:
            n1, n2 = (n[k], n[k + 1]) if action == "fwd" else (n[k + 1], n[k])
            if n1 != n2:
                cos_w = np.abs(dn) if fresnel == "exact" else 1.0
                weight = weight * (1.0 - reflectance(n1, n2, cos_w, surf.coating,
                                                     wavelength_nm))
                # vector Snell's law with the normal facing the incoming ray (-n where
                # d.n > 0): the sign flips are exact, so ci = -d.nn is |d.n| as computed
                eta = n1 / n2
                flip = dn > 0.0
                ci = np.where(flip, dn, -dn)
                k2 = 1.0 - eta * eta * (1.0 - ci * ci)
                ok &= k2 >= 0.0                       # total internal reflection: lost
                g = eta * ci - np.sqrt(np.maximum(k2, 0.0))
                g = np.where(flip, -g, g)             # g * nn = (-g) * n where flipped
                dx, dy, dz = eta * dx + g * nx, eta * dy + g * ny, eta * dz + g * nz
        ox, oy, oz = hx, hy, hz
        if not ok.all():
            keep = np.flatnonzero(ok)
            idx, ox, oy, oz, dx, dy, dz = (a.take(keep) for a in (idx, ox, oy, oz, dx, dy, dz))
            if fresnel == "exact":
                weight = weight.take(keep)
    # the image plane
    t = (z_vertex[-1] - oz) / dz
    ok = np.isfinite(t) & (t > 0.0)
    alive = np.zeros(m, bool)
    alive[idx[ok]] = True
    land = np.full((m, 2), np.nan)
    land[idx[ok], 0] = (ox + t * dx)[ok]
    land[idx[ok], 1] = (oy + t * dy)[ok]
    weights = np.zeros(m)
    weights[idx[ok]] = (weight[ok] if fresnel == "exact" else weight)
    return land, weights, alive


def trace(lens, path, field_deg, wavelength_nm, *, fresnel="normal", n_coarse=96,
          n_fine=200) -> Spot:
    """Shoot the beam of a distant light ``field_deg`` off the axis along ``path``.

    The coarse grid (``n_coarse`` rays across the first surface) doubles up to 384 while
    fewer than 16 rays survive (a ghost beam can be narrower than a coarse cell); the fine
    grid has ``n_fine`` rays across the paraxial zone's bounding box.
    """
    theta = np.radians(field_deg)
    direction = np.array([np.sin(theta), 0.0, np.cos(theta)])
    a0 = lens.surfaces[0].semi_aperture * 1.02

    def grid(x0, x1, y0, y1, nx):
        ny = nx
        xs = x0 + (np.arange(nx) + 0.5) * (x1 - x0) / nx
        ys = y0 + (np.arange(ny) + 0.5) * (y1 - y0) / ny
        gx, gy = np.meshgrid(xs, ys)
        return np.column_stack([gx.ravel(), gy.ravel()]), (x1 - x0) / nx, (y1 - y0) / ny

    def paraxial_zone(alive, n):
        """The survivors connected to the one nearest the axis (8-connected)."""
        labels, _ = ndimage.label(alive.reshape(n, n), structure=np.ones((3, 3)))
        labels = labels.ravel()
        r2 = np.where(alive, (pts ** 2).sum(axis=1), np.inf)
        return labels == labels[np.argmin(r2)]

    while True:
        pts, dx, dy = grid(-a0, a0, -a0, a0, n_coarse)
        _, weight, alive = _trace(lens, path, pts, direction, wavelength_nm, fresnel)
        if alive.sum() >= 16 or n_coarse >= 384:
            break
        n_coarse *= 2
    if not alive.any():
        return Spot(0, 0.0, 0.0, (np.nan, np.nan), np.nan, np.nan)
    zone = paraxial_zone(alive, n_coarse)
    other = float(weight[alive & ~zone].sum() * dx * dy * np.cos(theta))
    lo = pts[zone].min(axis=0) - 1.5 * np.array([dx, dy])
    hi = pts[zone].max(axis=0) + 1.5 * np.array([dx, dy])
    pts, dx, dy = grid(lo[0], hi[0], lo[1], hi[1], n_fine)
    land, weight, alive = _trace(lens, path, pts, direction, wavelength_nm, fresnel)
    if alive.any():
        alive &= paraxial_zone(alive, n_fine)
    cell = dx * dy * np.cos(theta)          # area perpendicular to the beam
    xy, w = land[alive], weight[alive]
    if not len(xy):
        return Spot(0, 0.0, 0.0, (np.nan, np.nan), np.nan, np.nan)
    centroid = (w[:, None] * xy).sum(axis=0) / w.sum()
    r2 = ((xy - centroid) ** 2).sum(axis=1)
    return Spot(n_rays=int(alive.sum()), area_mm2=float(alive.sum() * cell),
                power_mm2=float(w.sum() * cell), centroid=(float(centroid[0]),
                                                            float(centroid[1])),
                radius_mm=float(np.sqrt(2.0 * (w * r2).sum() / w.sum())),
                extent_mm=float(np.sqrt(r2.max())), other_power_mm2=other)


@dataclass(frozen=True)
class GhostReference:
    centre: float            # ghost centroid / light's image centroid (x), as the kernel uses
    radius_mm: float
    energy: float            # ghost power / light entering the entrance pupil
    spot: Spot
    primary: Spot


def ghost_reference(lens, i, j, field_deg, wavelength_nm, *, reference_nm=None,
                    fresnel="normal", primary=None, pupil=None, **kw) -> GhostReference:
    """The ghost ``(i, j)`` (reflect at ``i``, then ``j < i``) of a light ``field_deg`` off
    the axis, measured like :func:`clfx.fx.optics.ghosts` reports it.  ``primary`` (the
    light's own spot at ``reference_nm``) and ``pupil`` (at ``wavelength_nm``) may be
    passed in to trace them once for many ghosts."""
    ref = wavelength_nm if reference_nm is None else reference_nm
    if primary is None:
        primary = trace(lens, primary_path(lens), field_deg, ref, fresnel=fresnel, **kw)
    if pupil is None:
        pupil = primary if ref == wavelength_nm else trace(
            lens, primary_path(lens), field_deg, wavelength_nm, fresnel=fresnel, **kw)
    spot = trace(lens, ghost_path(lens, i, j), field_deg, wavelength_nm, fresnel=fresnel, **kw)
    return GhostReference(centre=spot.centroid[0] / primary.centroid[0],
                          radius_mm=spot.radius_mm, energy=spot.power_mm2 / pupil.area_mm2,
                          spot=spot, primary=primary)
