"""Describing a file: its parts, channels and windows, and how `clfx.io.read.read_frame` would
read it (``clfx probe``).  Only the depth pass and the beauty's alpha are read, to report how
the depth marks "no hit" (`clfx.io.channels.no_hit`)."""
from __future__ import annotations

from clfx.io import channels as ch
from clfx.io._oiio import win_json
from clfx.io.read import PassSpec, _scan, depth_no_hit, plan_read

_CONVENTION = {True: "y-up", False: "y-down"}


def probe(path, *, passes: PassSpec = PassSpec(), colorspace: str | None = None,
          depth_path=None, velocity_path=None, part: int | str | None = None,
          working_space: str | None = None, view: str | None = None) -> dict:
    """Describe a file and how `read_frame` would read it (of the pixels, only the depth
    and alpha are read: for ``depth.no_hit``).

    Returns
    -------
    dict
        JSON-able: ``file``, ``format``, ``parts`` (name, view, channels, windows, pixel
        aspect), ``view``, ``beauty``, ``depth`` and ``velocity`` (channel, part, mode or
        convention, ``why``; depth also ``no_hit``: how 0 and huge values were read) or None,
        ``rgb`` (False for a pass-only file: ``beauty`` None, its passes planned as a
        ``--depth`` / ``--velocity`` file's), ``ignored_other_views``, ``views`` (views with a beauty, hero first: all rendered by
        default), ``encoding``, ``colorspace`` (``from`` the file's space, ``to`` the working
        space, ``why``),
        ``search_order``.
    """
    plan = plan_read(path, passes, colorspace, depth_path, velocity_path, part, working_space,
                     view, passes_only=True)
    f = plan.file
    b = plan.beauty
    info = {
        "file": f.path,
        "format": f.format,
        "parts": [{"index": p.index, "name": p.name, "view": p.view,
                   "views": list(p.views), "channels": list(p.channels),
                   "formats": list(p.formats),
                   "data_window": win_json(p.data_window),
                   "display_window": win_json(p.display_window),
                   "pixel_aspect": p.pixel_aspect, "deep": p.deep} for p in f.parts],
        "view": plan.view,
        "beauty": b and {"part": b.part, "channels": b.channels, "grey": b.grey,
                         "why": b.why},
        "rgb": b is not None,
        "depth": None,
        "velocity": None,
        "ignored_other_views": ch.other_view_channels(f.dicts(), plan.view),
        "encoding": plan.encoding,
        "colorspace": {"from": plan.source_colorspace, "to": plan.working,
                       "why": plan.colour_why},
        "views": list(ch.beauty_views(f.dicts())),
        "search_order": ch.search_order(),
    }
    if plan.depth:
        d = plan.depth
        info["depth"] = {"file": d.path, "part": d.part.index, "channel": d.channels[0],
                         "rule": d.rule, "mode": d.mode, "scale": passes.depth_scale,
                         "data_window": win_json(d.part.data_window), "why": d.why}
        if d.mode == "normalized":
            info["depth"]["near_far"] = [passes.depth_near, passes.depth_far]
        info["depth"]["no_hit"] = depth_no_hit(plan, passes).as_dict()
    if plan.velocity:
        v = plan.velocity
        info["velocity"] = {"file": v.path, "part": v.part.index, "channels": list(v.channels),
                            "rule": v.rule, "direction": v.direction, "y_up": v.y_up,
                            "scale": passes.velocity_scale,
                            "convention": f"{v.direction}, pixels, {_CONVENTION[v.y_up]}"
                                          " -> clfx forward px/frame, +y down",
                            "data_window": win_json(v.part.data_window), "why": v.why}
    return info


def _pass_line(kind: str, p: dict | None, info: dict, channels: str, convention: str) -> str:
    if not p:
        return f"{kind}: none found"
    where = f" of {p['file']}" if p["file"] != info["file"] else ""
    return (f"{kind}: {channels} (part {p['part']}{where}), {convention}, "
            f"scale {p['scale']:g}  ({p['why']})")


def format_probe(info: dict) -> str:
    """Human-readable lines for a `probe` result."""
    def win(w):
        return f"({w['x']},{w['y']}) {w['width']}x{w['height']}"

    lines = [f"{info['file']}  [{info['format']}]"]
    for p in info["parts"]:
        name = f" {p['name']!r}" if p["name"] else ""
        view = f" view={p['view']}" if p["view"] else ""
        views = f" views={','.join(p['views'])}" if p["views"] else ""
        lines.append(f"  part {p['index']}{name}{view}{views}: data {win(p['data_window'])}, "
                     f"display {win(p['display_window'])}, pixel aspect {p['pixel_aspect']:g}"
                     + (" DEEP" if p["deep"] else ""))
        lines.append(f"    channels: {', '.join(p['channels'])}")
    b = info["beauty"]
    if b is None:
        lines.append("beauty: none (no R,G,B or grey channels): a pass-only file; render "
                     "it as --depth or --velocity beside a beauty")
    else:
        lines.append(f"beauty: part {b['part']} {', '.join(b['channels'])}  ({b['why']})")
    if info.get("view"):
        lines.append(f"view: {info['view']}  (views with a beauty: "
                     f"{', '.join(info['views']) or 'none'}; all are rendered unless --view)")
    d, v = info["depth"], info["velocity"]
    lines.append(_pass_line("depth", d, info, d and d["channel"], d and f"mode {d['mode']}"))
    if d:
        lines.append(f"  no hit: {d['no_hit']['assumed']}")
    lines.append(_pass_line("velocity", v, info, v and "/".join(v["channels"]),
                            v and v["convention"]))
    if info["ignored_other_views"]:
        lines.append(f"ignored (other views): {', '.join(info['ignored_other_views'])}")
    cs = info["colorspace"]
    lines.append(f"encoding: {info['encoding']}  (colour: {cs['from']} -> working space "
                 f"{cs['to']}; {cs['why']})")
    lines.append("search order:")
    for kind, order in info["search_order"].items():
        lines.append(f"  {kind}: " + " > ".join(order))
    return "\n".join(lines)


def header_attribute(path, name: str):
    """The value of header attribute ``name`` in the first part of ``path`` that has it
    (whatever its length: `Frame.metadata` skips long strings), or None."""
    for part in _scan(path).parts:
        value = part.spec.getattribute(name)
        if value is not None:
            return value
    return None
