"""The ``clfx`` command line (click).

Exit codes: 0 success; 1 processing error (bad input file, failed frame, bad look, no
device); 2 usage error (unknown option, bad argument); 130 interrupted (Ctrl-C), 143
terminated (SIGTERM).  Interruptions leave no partial output: every write goes to a temp file
in the output folder and is renamed into place only when complete.

stdout carries only data (``--json`` lines, listings); progress and logs go to stderr, and
progress is shown only when stderr is a terminal and ``-q`` is not given.
"""
from __future__ import annotations

import json
import math
import signal
import sys
from concurrent.futures import ThreadPoolExecutor

import click

from clfx import __version__
from clfx.core.errors import ClfxError

EXIT_INTERRUPTED = 130
EXIT_TERMINATED = 143


class _Terminated(BaseException):
    """Raised from the SIGTERM handler so that cleanup (temp-file removal) runs."""


def _on_sigterm(signum, frame):
    raise _Terminated()


class ClfxClickError(click.ClickException):
    """A ClfxError shown as one line (``clfx: error: ...``) with exit code 1."""

    exit_code = 1

    def show(self, file=None):
        click.echo(f"clfx: error: {self.message}", err=True)


class ClfxGroup(click.Group):
    """Turns every ClfxError raised by a subcommand into a one-line error, exit code 1."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except ClfxError as exc:
            msg = str(exc)
            # Build logs keep their lines; everything else is one line.
            raise ClfxClickError(msg if "\n" in msg and "build" in msg else " ".join(msg.split())) from exc


def _runtime(ctx: click.Context):
    from clfx.device.runtime import Runtime

    return Runtime.get(ctx.obj.get("device") if ctx.obj else None)


def _runtime_soon(ctx: click.Context):
    """Start creating the runtime on a thread (OpenCL releases the GIL), so device set-up
    overlaps loading the look and reading the first frame; call ``.result()`` for it."""
    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="clfx-device")
    future = pool.submit(_runtime, ctx)
    pool.shutdown(wait=False)
    return future


@click.group(cls=ClfxGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="clfx")
@click.option("-v", "--verbose", count=True, help="More messages on stderr.")
@click.option("-q", "--quiet", is_flag=True, help="No progress or messages on stderr.")
@click.option("--device", envvar="CLFX_DEVICE", default=None, metavar="SEL",
              help="OpenCL device: 'P:D' indices or a name substring (env CLFX_DEVICE).")
@click.pass_context
def cli(ctx, verbose, quiet, device):
    """clfx: camera-defect effects (depth of field, motion blur, glare, grain, ...) for
    image sequences, on OpenCL."""
    ctx.ensure_object(dict)
    ctx.obj["verbosity"] = 0 if quiet else 1 + verbose
    ctx.obj["device"] = device


# -- inspection ----------------------------------------------------------------------------
@cli.command()
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
@click.pass_context
def devices(ctx, as_json):
    """List every OpenCL platform and device, mark the one in use, say why others are not."""
    from clfx.device.runtime import INSTALL_HINT, survey_devices

    reports, chosen = survey_devices(ctx.obj.get("device"))
    if as_json:
        click.echo(json.dumps([r.__dict__ for r in reports], indent=2))
    else:
        for r in reports:
            mark = "*" if r.chosen else " "
            click.echo(f"{mark} [{r.index}] {r.label} ({r.kind}, {r.version}"
                       f"{', fp64' if r.fp64 else ''}): {r.reason}")
    if chosen is None:
        raise ClfxError(f"no usable OpenCL device; {INSTALL_HINT}")


@cli.command()
@click.option("--json", "as_json", is_flag=True)
def plugins(as_json):
    """List the effects."""
    from clfx.plugins import discover

    reg = discover()
    if as_json:
        click.echo(json.dumps([cls.descriptor.describe() for cls in reg.values()], indent=2))
        return
    for name, cls in reg.items():
        d = cls.descriptor
        click.echo(f"{name:<22} {d.group:<10} v{d.version[0]}.{d.version[1]}  {d.summary}")


@cli.command()
@click.argument("effect")
@click.option("--json", "as_json", is_flag=True)
def describe(effect, as_json):
    """Print an effect's full descriptor: parameters, clips, quality levels."""
    from clfx.plugins import get_plugin

    d = get_plugin(effect).descriptor.describe()
    if as_json:
        click.echo(json.dumps(d, indent=2))
        return
    click.echo(f"{d['name']} ({d['label']}, group {d['group']}, version {d['version']})")
    click.echo(f"  {d['summary']}")
    click.echo(f"  kernel: kernels/{d['kernel']}   spreads light: {d['spreads_light']}   "
               f"varies per frame: {d['frame_varying']}")
    click.echo("clips:")
    for c in d["clips"]:
        click.echo(f"  {c['name']:<10} {'optional' if c['optional'] else 'required'}, "
                   f"{c['channels']} channel(s)  {c['hint']}")
    click.echo("parameters:")
    for p in d["params"]:
        rng = ""
        if "choices" in p:
            rng = " {" + ", ".join(p["choices"]) + "}"
        elif "min" in p:
            rng = f" [{p['min']}, {p['max']}]"
        units = f" {p['units']}" if p.get("units") else ""
        click.echo(f"  {p['name']:<18} {p['type']:<8} default {p['default']!r}{rng}{units}")
        if p["hint"]:
            click.echo(f"  {'':<18} {p['hint']}")
    click.echo("quality levels:")
    for lvl, text in d["quality"].items():
        click.echo(f"  {lvl:<10} {text}")
        settings = ", ".join(f"{k}={v}" for k, v in d["quality_settings"][lvl].items())
        if settings:
            click.echo(f"  {'':<10} ({settings})")


@cli.command()
@click.option("--json", "as_json", is_flag=True)
def looks(as_json):
    """List the looks (built-in, user and CLFX_PRESET_PATH)."""
    from clfx.pipeline.presets import available_looks, load_look

    rows = []
    for name, (origin, path) in available_looks().items():
        try:
            look = load_look(str(path))
            rows.append({"name": name, "origin": origin, "path": str(path),
                         "description": look.description,
                         "effects": [s.effect for s in look.steps]})
        except ClfxError as exc:
            rows.append({"name": name, "origin": origin, "path": str(path), "error": str(exc)})
    if as_json:
        click.echo(json.dumps(rows, indent=2))
        return
    for r in rows:
        if "error" in r:
            click.echo(f"{r['name']:<20} {r['origin']:<9} INVALID: {r['error']}")
        else:
            click.echo(f"{r['name']:<20} {r['origin']:<9} {r['description']}")
            click.echo(f"{'':<31}effects: {', '.join(r['effects']) or '(none)'}")


@cli.group(cls=ClfxGroup)
def look():
    """Inspect looks."""


@look.command("show")
@click.argument("name")
@click.option("--set", "assignments", multiple=True, metavar="K=V")
@click.option("--json", "as_json", is_flag=True)
def look_show(name, assignments, as_json):
    """Print the resolved look (inheritance applied, defaults filled in)."""
    from clfx.pipeline.presets import apply_overrides, load_look

    lk = apply_overrides(load_look(name), list(assignments))
    d = lk.describe()
    d["params_hash"] = lk.params_hash()
    if as_json:
        click.echo(json.dumps(d, indent=2))
        return
    click.echo(f"{lk.name}: {lk.description}")
    click.echo(f"  file: {lk.source}" + (f"   base: {lk.base}" if lk.base else ""))
    click.echo(f"  seed: {lk.seed}   params hash: {d['params_hash']}")
    click.echo("  camera: " + ", ".join(f"{k}={v}" for k, v in d["camera"].items()))
    for i, s in enumerate(d["effects"], 1):
        q = f" (quality {s['quality']})" if "quality" in s else ""
        click.echo(f"  {i}. {s['effect']}{q}")
        for k, v in s["params"].items():
            click.echo(f"       {k} = {v!r}")


@cli.command()
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True)
@click.pass_context
def probe(ctx, file, as_json, **kw):
    """Print the channels, windows and passes found in FILE and how they will be read."""
    from clfx.io.probe import format_probe, probe as probe_file

    info = probe_file(file, passes=_pass_spec(ctx.params), colorspace=kw.get("colorspace"),
                      working_space=kw.get("working_space"), view=kw.get("view"))
    click.echo(json.dumps(info, indent=2, default=str) if as_json else format_probe(info))


@cli.command()
@click.argument("query", default="")
@click.option("--limit", default=50, show_default=True)
@click.option("--json", "as_json", is_flag=True)
def lenses(query, limit, as_json):
    """Find real lenses in the lensfun database (for the `lens` effect)."""
    from clfx.fx.lensdb import find_lenses

    rows = find_lenses(query, limit=limit)
    if as_json:
        click.echo(json.dumps(rows, indent=2, default=str))
        return
    if not rows:
        raise ClfxError(f"no lens in the lensfun database matches {query!r}")
    for r in rows:
        click.echo("  ".join(f"{v}" for v in r.values()))


# -- shared options for render / apply -----------------------------------------------------
def _io_options(f):
    opts = [
        click.option("--frames", default=None, metavar="SPEC",
                     help="Frames to render: 1-100, 1-100x2, 1,5,10-20, farm a-b:n. Default: all on disk."),
        click.option("--quality", type=click.Choice(["draft", "preview", "final", "reference"]),
                     default=None, help="Quality level of every effect without its own override."),
        click.option("--depth", "depth_path", default=None, metavar="PATTERN",
                     help="Depth pass from separate files (pattern like the input)."),
        click.option("--velocity", "velocity_path", default=None, metavar="PATTERN",
                     help="Velocity pass from separate files."),
        click.option("--depth-channel", default=None, help="Depth channel name (overrides detection)."),
        click.option("--depth-mode", type=click.Choice(["auto", "z", "inverse", "distance", "normalized"]),
                     default="auto", help="How depth is stored: planar z, 1/z, radial distance, 0-1."),
        click.option("--depth-scale", type=float, default=1.0, help="Multiply depth (e.g. 0.01 for cm to m)."),
        click.option("--depth-zero", type=click.Choice(["auto", "far", "invalid"]), default="auto",
                     help="Depth 0: far = no hit (infinitely far), invalid = kept (in focus); "
                          "auto decides from its share and alpha."),
        click.option("--depth-far-threshold", type=float, default=1e9, metavar="Z",
                     help="Depths of at least this magnitude are no hit (inf keeps them)."),
        click.option("--focal-length-px", type=float, default=None,
                     help="For --depth-mode distance: focal length in pixels (default: from the "
                          "look's camera block and the frame width)."),
        click.option("--velocity-channels", default=None, metavar="U,V", help="Velocity channel names."),
        click.option("--velocity-y-up/--velocity-y-down", default=None,
                     help="Direction of +v in the velocity pass (overrides detection)."),
        click.option("--velocity-scale", type=float, default=1.0, help="Multiply velocity."),
        click.option("--colorspace", default=None,
                     help="Colour space of the input (OCIO name or alias, 'raw'); default: the "
                          "file's tag or chromaticities, else sRGB for 8/16-bit, linear Rec.709."),
        click.option("--out-colorspace", default=None,
                     help="Colour space to write the output in (default: the input's)."),
        click.option("--working-space", default=None, metavar="SPACE",
                     help="Linear space effects work in: lin_rec709 (default), ACEScg, ..."),
        click.option("--passes", type=click.Choice(["keep", "drop"]), default="keep",
                     help="keep: write every other channel and part of the input through "
                          "unchanged (EXR); drop: the beauty only."),
        click.option("--view", default=None, metavar="NAME",
                     help="Multi-view input: render this view only (default: every view)."),
        click.option("--float", "as_float", is_flag=True,
                     help="Write the EXR beauty as 32-bit float (default: the input's type)."),
        click.option("--compression", default=None,
                     help="EXR compression: zip, piz, dwaa, none, ... (default: the input's)."),
        click.option("--overwrite", is_flag=True, help="Replace existing outputs."),
        click.option("--skip-existing", is_flag=True, help="Skip frames whose output exists (resume a batch)."),
        click.option("--skip-missing", is_flag=True, help="Skip missing input frames instead of failing."),
        click.option("--keep-overscan", is_flag=True, help="Keep light spread past the display window."),
        click.option("--raw", "raw_size", default=None, metavar="WxH",
                     help="With '-' as INPUT/OUTPUT: raw gbrpf32le frames on stdin/stdout (ffmpeg)."),
        click.option("--explain", is_flag=True, help="Per frame: which effects ran, which were skipped and why."),
        click.option("--json", "as_json", is_flag=True, help="One JSON line per frame and a summary on stdout."),
    ]
    for o in reversed(opts):
        f = o(f)
    return f


def _pass_spec(kw, focal_length_px: float | None = None):
    """The pass overrides given on the command line (focal length for radial depth given
    by --focal-length-px or derived by the caller)."""
    from clfx.io.read import PassSpec

    vc = kw.get("velocity_channels")
    for name in ("depth_scale", "velocity_scale"):
        value = kw.get(name, 1.0)
        if not (value > 0 and math.isfinite(value)):
            raise click.BadParameter(f"{value} must be a positive number",
                                     param_hint=f"--{name.replace('_', '-')}")
    return PassSpec(depth_channel=kw.get("depth_channel"), depth_mode=kw.get("depth_mode") or "auto",
                    depth_scale=kw.get("depth_scale", 1.0),
                    velocity_channels=tuple(vc.split(",")) if vc else None,
                    velocity_y_up=kw.get("velocity_y_up"),
                    velocity_scale=kw.get("velocity_scale", 1.0),
                    focal_length_px=kw.get("focal_length_px") or focal_length_px,
                    depth_zero=kw.get("depth_zero") or "auto",
                    depth_far_threshold=kw.get("depth_far_threshold") or 1e9)


for _cmd in (probe,):
    for _o in reversed([
        click.option("--depth-channel", default=None), click.option("--depth-mode", default="auto",
            type=click.Choice(["auto", "z", "inverse", "distance", "normalized"])),
        click.option("--depth-scale", type=float, default=1.0),
        click.option("--depth-zero", type=click.Choice(["auto", "far", "invalid"]), default="auto"),
        click.option("--depth-far-threshold", type=float, default=1e9),
        click.option("--focal-length-px", type=float, default=None),
        click.option("--velocity-channels", default=None, metavar="U,V"),
        click.option("--velocity-y-up/--velocity-y-down", default=None),
        click.option("--velocity-scale", type=float, default=1.0),
        click.option("--colorspace", default=None), click.option("--working-space", default=None),
        click.option("--view", default=None)]):
        _o(_cmd)


@cli.command()
@click.argument("input_path", metavar="INPUT")
@click.argument("output_path", metavar="OUTPUT")
@click.option("--look", "look_name", default="default", show_default=True,
              help="Look name or YAML file.")
@click.option("--set", "assignments", multiple=True, metavar="K=V",
              help="Override: effect.param=value, camera.key=value, seed=N.")
@_io_options
@click.pass_context
def render(ctx, input_path, output_path, look_name, assignments, **kw):
    """Render INPUT (file or sequence pattern like shot.####.exr) through a look to OUTPUT."""
    runtime = _runtime_soon(ctx)
    from clfx.pipeline.presets import apply_overrides, load_look

    lk = apply_overrides(load_look(look_name), list(assignments))
    _run_batch(ctx, lk, input_path, output_path, kw, runtime)


@cli.command()
@click.argument("effect")
@click.argument("input_path", metavar="INPUT")
@click.argument("output_path", metavar="OUTPUT")
@click.argument("assignments", nargs=-1, metavar="[PARAM=VALUE]...")
@_io_options
@click.pass_context
def apply(ctx, effect, input_path, output_path, assignments, **kw):
    """Apply one EFFECT to INPUT with PARAM=VALUE settings (camera.key=value too)."""
    runtime = _runtime_soon(ctx)
    from clfx.pipeline.presets import single_effect_look

    lk = single_effect_look(effect, list(assignments))
    _run_batch(ctx, lk, input_path, output_path, kw, runtime)


def _radial_depth_focal_px(kw, lk, batch) -> float | None:
    """Focal length in pixels for --depth-mode distance, from the look's camera block and the
    first input's display width (square pixels assumed, as the camera block does)."""
    if kw.get("depth_mode") != "distance" or kw.get("focal_length_px") or not batch.jobs:
        return None
    from clfx.io.probe import probe as probe_file

    info = probe_file(batch.jobs[0].input)
    width = info["parts"][info["beauty"]["part"]]["display_window"]["width"]
    return lk.camera.focal_length_px(width)


def _run_batch(ctx, lk, input_path, output_path, kw, runtime):
    from clfx.pipeline.batch import Batch

    verbosity = ctx.obj.get("verbosity", 1)
    batch = Batch(look=lk, input_path=input_path, output_path=output_path, options=kw,
                  passes=None, verbosity=verbosity,
                  progress=verbosity > 0 and sys.stderr.isatty() and not kw.get("as_json"))
    batch.prepare()  # everything checked before the first frame is read
    batch.passes = _pass_spec(kw, _radial_depth_focal_px(kw, lk, batch))
    with batch.reading():  # the first frame is read while the device finishes setting up
        batch.run(runtime.result())


@cli.command()
@click.argument("outdir", default="clfx-demo", required=False)
@click.option("--frames", "count", default=24, show_default=True, help="Number of frames.")
@click.option("--size", default="640x360", show_default=True, help="WxH.")
@click.option("--look", "look_name", default="default", show_default=True)
@click.option("--quality", type=click.Choice(["draft", "preview", "final", "reference"]), default=None)
@click.option("--overwrite/--no-overwrite", default=True, show_default=True)
@click.option("--explain", is_flag=True)
@click.option("--json", "as_json", is_flag=True)
@click.pass_context
def demo(ctx, outdir, count, size, look_name, quality, overwrite, explain, as_json):
    """Render the built-in procedural HDR scene through a look: EXRs, PNG previews and a
    contact sheet in OUTDIR.  Needs no input files."""
    from clfx.demo import run_demo

    w, h = _parse_size(size)
    run_demo(_runtime(ctx), outdir, count=count, width=w, height=h, look_name=look_name,
             quality=quality, overwrite=overwrite, explain=explain, as_json=as_json,
             verbosity=ctx.obj.get("verbosity", 1))


@cli.command()
@click.option("--effects", default=None, metavar="A,B",
              help="Effects to measure (default: all; 'none' to skip).")
@click.option("--looks", default=None, metavar="A,B",
              help="Looks to measure (default: every built-in look; 'none' to skip).")
@click.option("--size", default="1920x1080", show_default=True, help="WxH of the bench frames.")
@click.option("--repeat", default=5, show_default=True, help="Warm runs per measurement (median).")
@click.option("--sequence-frames", default=8, show_default=True,
              help="Frames for the sequence-throughput measurement (0 to skip).")
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON on stdout.")
@click.option("--plot", "plot_path", default=None, metavar="FILE", help="Pareto plot PNG (matplotlib).")
@click.option("--markdown", "md_path", default=None, metavar="FILE", help="Write the tables as markdown.")
@click.pass_context
def bench(ctx, effects, looks, size, repeat, sequence_frames, as_json, plot_path, md_path):
    """What accuracy costs in time: every effect at every quality level against its reference
    (with OpenCV/SciPy peers), whole looks, sequence throughput, and scene-analysis skipping."""
    from clfx.bench.runner import markdown, pareto_plot, run_bench

    w, h = _parse_size(size)
    look_list = None if looks is None else ([] if looks == "none" else looks.split(","))
    verbose = ctx.obj.get("verbosity", 1) > 0
    effect_list = None if effects is None else ([] if effects == "none" else effects.split(","))
    results = run_bench(_runtime(ctx), effects=effect_list,
                        looks=look_list, width=w, height=h, repeat=max(1, repeat),
                        sequence_frames=sequence_frames,
                        log=(lambda m: click.echo(m, err=True)) if verbose else (lambda m: None))
    table = markdown(results)
    if md_path:
        with open(md_path, "w") as f:
            f.write(table)
    if plot_path:
        pareto_plot(results, plot_path)
    if as_json:
        click.echo(json.dumps(results, default=lambda o: None if isinstance(o, float) and not math.isfinite(o) else str(o)))
    else:
        click.echo(table)


def _parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
        if w < 1 or h < 1:
            raise ValueError
        return w, h
    except ValueError:
        raise click.BadParameter(f"{text!r} is not WxH (e.g. 1920x1080)") from None


def main(argv=None):
    """Entry point: ClfxError -> one line and exit 1; interrupts -> no partial files."""
    signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        cli.main(args=argv, prog_name="clfx", standalone_mode=False)
    except click.exceptions.Abort:
        click.echo("clfx: interrupted", err=True)
        sys.exit(EXIT_INTERRUPTED)
    except click.ClickException as exc:
        exc.show()
        sys.exit(exc.exit_code)
    except ClfxError as exc:  # raised outside a subcommand (e.g. while parsing)
        ClfxClickError(" ".join(str(exc).split())).show()
        sys.exit(1)
    except KeyboardInterrupt:
        click.echo("clfx: interrupted", err=True)
        sys.exit(EXIT_INTERRUPTED)
    except _Terminated:
        click.echo("clfx: terminated", err=True)
        sys.exit(EXIT_TERMINATED)
    except BrokenPipeError:
        sys.exit(1)
    sys.exit(0)


if __name__ == "__main__":  # pragma: no cover
    main()
