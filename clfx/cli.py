"""The ``clfx`` command line (click).

Exit codes: 0 success; 1 processing error (bad input file, failed frame, bad look, no
device); 2 usage error (unknown option, bad argument: one line too); 130 interrupted
(Ctrl-C), 143 terminated (SIGTERM).  Interruptions leave no partial output: every write goes
to a temp file in the output folder and is renamed into place only when complete.  A closed
stdin or stdout, or a write to stdout that fails (a full disk), is one error line and exit
code 1.

stdout carries only data (``--json`` lines, listings); progress and logs go to stderr, and
progress is shown only when stderr is a terminal and ``-q`` is not given.  ``-q`` and ``-v``
may come before or after the command (``clfx render A B -q``); ``-q`` keeps the warnings
about what clfx assumed (a depth pass's "no hit" convention, ``####`` as 16 digits).
"""
from __future__ import annotations

import contextlib
import difflib
import json
import math
import os
import shlex
import signal
import stat
import sys
import threading
import time
import warnings
from dataclasses import replace

import click

from clfx._version import __version__
from clfx.cli_options import (check_frames, colour_options, pass_options, quality_option,
                               render_options)
from clfx.core.errors import ClfxError, PresetError, speak

EXIT_INTERRUPTED = 130
EXIT_TERMINATED = 143


class _Terminated(BaseException):
    """Raised from the SIGTERM handler so that cleanup (temp-file removal) runs."""


def _on_sigterm(signum, frame):
    raise _Terminated()


_ENDED: list[bool] = []
"""Not empty once the main thread has said how the process ends (`_say_end`): the signal
watcher then ends it without a second line."""


def _say_end(text: str) -> None:
    click.echo(text, err=True)
    _ENDED.append(True)


class StdioError(ClfxError):
    """stdin or stdout is closed, or writing to stdout failed (a full disk, /dev/full)."""


def _to_devnull(stream) -> None:
    """Point ``stream``'s descriptor at /dev/null: what is still buffered for it (the
    interpreter flushes it at exit) then goes nowhere instead of failing a second time."""
    try:
        fd = stream.fileno()
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, fd)
        os.close(null)
    except (AttributeError, OSError, ValueError):
        pass


class _GuardedStream:
    """sys.stdin / sys.stdout while the CLI runs: a closed descriptor (the stream is None)
    or a failed write is a :class:`StdioError` (one line, exit code 1), not a traceback.
    A broken pipe passes through (the reader went away: exit quietly).  A failure sticks:
    later writes fail the same way (click probes streams and swallows what they raise)."""

    def __init__(self, stream, name: str):
        self._stream, self._name = stream, name
        self._failed: str | None = None

    def __getattr__(self, attr):
        if self._stream is None:
            if attr in ("encoding", "errors"):
                return "utf-8" if attr == "encoding" else "strict"
            raise AttributeError(attr)
        return getattr(self._stream, attr)

    @property
    def buffer(self):
        return _GuardedStream(getattr(self._stream, "buffer", None), self._name)

    def isatty(self) -> bool:
        return self._stream is not None and self._stream.isatty()

    def write(self, data):
        return self._do("write", data)

    def read(self, *args):
        return self._do("read", *args)

    def flush(self):
        if self._stream is not None:
            self._do("flush")

    def _do(self, op: str, *args):
        if self._stream is None:
            raise StdioError(f"{self._name} is closed")
        if self._failed:
            raise StdioError(self._failed)
        try:
            return getattr(self._stream, op)(*args)
        except BrokenPipeError:
            raise
        except OSError as exc:
            _to_devnull(self._stream)
            verb = "read" if op == "read" else "write to"
            self._failed = f"cannot {verb} {self._name}: {exc.strerror or exc}"
            raise StdioError(self._failed) from None


class ClfxClickError(click.ClickException):
    """A ClfxError shown as one line (``clfx: error: ...``) with exit code 1."""

    exit_code = 1

    def show(self, file=None):
        click.echo(f"clfx: error: {self.message}", err=True)


class ClfxUsageError(click.UsageError):
    """A usage error shown as one line (``clfx: error: ...``, naming the command's help)
    with exit code 2, not click's three-line form."""

    def show(self, file=None):
        where = f" (see {self.ctx.command_path} --help)" if self.ctx is not None else ""
        click.echo(f"clfx: error: {' '.join(self.format_message().split())}{where}", err=True)


GROUP_OPTIONS = ("--device",)
"""Options of the ``clfx`` group itself that only it takes: given after a command, they are
named as such.  ``-q`` and ``-v`` are taken anywhere (`_verbosity_options`)."""


def _set_verbosity(ctx: click.Context, param, value) -> None:
    """``-q`` / ``-v`` given after a command (``clfx render A B -q``): the same as before it.
    Any ``-q`` wins over ``-v``."""
    if not value:
        return
    obj = ctx.find_root().ensure_object(dict)
    if param.name == "quiet":
        obj["quiet"] = True
    else:
        obj["verbose"] = obj.get("verbose", 0) + value
    obj["verbosity"] = 0 if obj.get("quiet") else 1 + obj.get("verbose", 0)
    _compiler_messages(obj["verbosity"])


def _verbosity_options(command: click.Command) -> None:
    """Give ``command`` the group's ``-q`` and ``-v`` (hidden in its help), unless it has
    options of those names itself."""
    taken = {o for p in command.params for o in getattr(p, "opts", ())}
    if not taken & {"-q", "--quiet"}:
        command.params.append(click.Option(["-q", "--quiet"], is_flag=True, hidden=True,
                                           expose_value=False, callback=_set_verbosity))
    if not taken & {"-v", "--verbose"}:
        command.params.append(click.Option(["-v", "--verbose"], count=True, hidden=True,
                                           expose_value=False, callback=_set_verbosity))


def _one_line_usage(exc: click.UsageError) -> click.UsageError:
    """``exc`` as a `ClfxUsageError`; a request for help (a bare group) stays as it is."""
    if isinstance(exc, ClfxUsageError) or type(exc).__name__ == "NoArgsIsHelpError":
        return exc
    message = exc.format_message()
    if isinstance(exc, click.NoSuchOption) and exc.option_name in GROUP_OPTIONS:
        message = (f"{exc.option_name} goes before the command (clfx {exc.option_name} "
                   f"{exc.ctx.info_name if exc.ctx else 'COMMAND'} ...)")
    out = ClfxUsageError(message, exc.ctx)
    out.exit_code = exc.exit_code
    return out


class ClfxGroup(click.Group):
    """Turns every ClfxError raised by a subcommand into a one-line error, exit code 1; the
    root group keeps the arguments it was given (stamped into outputs)."""

    def add_command(self, cmd, name=None):
        _verbosity_options(cmd)
        super().add_command(cmd, name)

    def make_context(self, info_name, args, parent=None, **extra):
        argv = list(args)
        try:
            ctx = super().make_context(info_name, args, parent=parent, **extra)
        except click.UsageError as exc:     # the group's own options (clfx --bogus)
            one = _one_line_usage(exc)
            if one is exc:
                raise
            raise one from exc
        if parent is None:
            ctx.meta["clfx.argv"] = argv
        return ctx

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except click.UsageError as exc:
            one = _one_line_usage(exc)
            if one is exc:
                raise
            raise one from exc
        except ClfxError as exc:
            msg = str(exc)
            # Build logs keep their lines; everything else is one line.
            raise ClfxClickError(msg if "\n" in msg and "build" in msg else " ".join(msg.split())) from exc


def _runtime(ctx: click.Context):
    # lazy: the device (pyopencl) is ~0.3 s at start-up; only device commands need it
    from clfx.device.runtime import Runtime

    return Runtime.get(ctx.obj.get("device") if ctx.obj else None)


def _check_first_frame(input_path: str, options) -> None:
    """Refuse a first frame whose windows exceed the pixel limits from its header, before
    the device is set up on a thread (`clfx.pipeline.preflight.check_first_frame`)."""
    # lazy: the render stack (device, OpenImageIO, looks) is ~1 s; --help must not wait
    from clfx.pipeline.preflight import check_first_frame

    check_first_frame(input_path, options)


def _runtime_soon(ctx: click.Context):
    """Start creating the runtime on a thread (`clfx.api.runtime_soon`), so device set-up
    overlaps loading the look and reading the first frame; call ``.result()`` for it."""
    # lazy: the render stack (device, OpenImageIO, looks) is ~1 s; --help must not wait
    from clfx.api import runtime_soon

    return runtime_soon(ctx.obj.get("device") if ctx.obj else None)


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
    ctx.obj.update(quiet=quiet, verbose=verbose)
    speak("cli")      # errors name options as flags (--overwrite), not API keywords
    ctx.call_on_close(lambda: speak("api"))
    ctx.obj["verbosity"] = 0 if quiet else 1 + verbose
    ctx.obj["device"] = device
    _compiler_messages(ctx.obj["verbosity"])


def _compiler_messages(verbosity: int) -> None:
    """OpenCL compiler output (pyopencl's CompilerWarning, PoCL's "N warnings generated.",
    caught by the runtime as a KernelBuildWarning) is shown only with -v: then with the
    whole build log."""
    # lazy: the device (pyopencl) is ~0.3 s at start-up; only device commands need it
    from clfx.device import runtime
    from clfx.device.runtime import KernelBuildWarning

    said = verbosity > 0 and os.environ.get("CLFX_COLD_NOTICE", "1") != "0"
    runtime.cold_build_notice = _cold_build_notice if said else None
    if verbosity >= 2:
        os.environ.setdefault("PYOPENCL_COMPILER_OUTPUT", "1")
        warnings.filterwarnings("always", category=KernelBuildWarning)
    else:
        warnings.filterwarnings("ignore", category=KernelBuildWarning)
        # pyopencl's own category, without importing pyopencl (slow) before it is needed
        warnings.filterwarnings("ignore", message=r"(?s).*(Non-empty compiler output|"
                                r"From-source build succeeded|Built kernel retrieved)")


COLD_BUILD_S_PER_STEP = 7
"""Seconds a cold kernel cache adds per step of a look, roughly (the cinema look's 8 steps at
1920x1080: 65 s cold, 7.3 s warm, on the 2-core PoCL machine): the ``~N s`` of the notice."""

_cold_steps: list[int] = []   # steps of the look this command renders (`_run_batch`)


def _cold_build_notice(rt) -> None:
    """Said once per process, before its first compile on a cold kernel cache (not with -q,
    nor with ``CLFX_COLD_NOTICE=0``): why the first render is slow and where the compiled
    kernels are kept."""
    where = rt.kernel_cache_dir
    kept = f"cached in {where}" if where else "cached by the OpenCL driver"
    eta = f": ~{COLD_BUILD_S_PER_STEP * _cold_steps[-1]} s" if _cold_steps else ""
    click.echo(f"clfx: compiling kernels for {rt.description} once ({kept}){eta}; "
               f"`clfx prebuild` does it ahead of renders", err=True)


# -- inspection ----------------------------------------------------------------------------
@cli.command()
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
@click.pass_context
def devices(ctx, as_json):
    """List every OpenCL platform and device, mark the one in use, say why others are not."""
    # lazy: the device (pyopencl) is ~0.3 s at start-up; only device commands need it
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
    # lazy: the effect registry is ~90 ms at start-up
    from clfx.plugins import discover

    reg = discover()
    if as_json:
        click.echo(json.dumps([cls.descriptor.describe() for cls in reg.values()], indent=2))
        return
    for name, cls in reg.items():
        d = cls.descriptor
        click.echo(f"{name:<22} {d.group:<10} v{d.version[0]}.{d.version[1]}  {d.summary}")


def _check_render_args(args) -> None:
    """Options passed through to every farm task (after ``--``) are parsed as ``clfx
    render`` parses them, so an unknown option or a bad value fails here, not on every task
    of the farm."""
    try:
        render.make_context("render", ["IN.#.exr", "OUT.#.exr", *args],
                            parent=click.get_current_context(silent=True))
    except click.UsageError as exc:
        raise click.UsageError(f"after '--' (clfx render options for every task): "
                               f"{exc.format_message()}") from None


@cli.command()
@click.argument("effect")
@click.option("--json", "as_json", is_flag=True)
def describe(effect, as_json):
    """Print an effect's full descriptor: parameters, clips, quality levels."""
    # lazy: the effect registry is ~90 ms at start-up
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
    # lazy: the render stack (device, OpenImageIO, looks) is ~1 s; --help must not wait
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
@click.option("--frame", type=int, default=None, metavar="N",
              help="Resolve keyframed values at frame N.")
@quality_option
@click.option("--json", "as_json", is_flag=True)
def look_show(name, assignments, frame, quality, as_json):
    """Print the resolved look (inheritance applied, defaults filled in); NAME is a look, a
    YAML file or an output clfx rendered (its stamped look).  Its params hash is the
    ``clfx:paramsHash`` a render at ``--quality`` (default final) stamps."""
    # lazy: the render stack (device, OpenImageIO, looks) is ~1 s; --help must not wait
    from clfx.api import load_look

    full = load_look(name, set=assignments)
    lk = full if frame is None else full.at(frame)
    d = lk.describe()
    d["params_hash"] = full.params_hash(quality)
    d["quality"] = quality or "final"
    for step, shown in zip(lk.steps, d["effects"]):
        shown["from"] = step.origin or lk.name
        if step.changed_in:
            shown["changed_in"] = list(step.changed_in)
    if frame is not None:
        d["frame"] = frame
        d["values"] = full.values_at(frame)
    if as_json:
        click.echo(json.dumps(d, indent=2))
        return
    click.echo(f"{lk.name}: {lk.description}")
    click.echo(f"  file: {lk.source}" + (f"   base: {lk.base}" if lk.base else ""))
    click.echo(f"  seed: {lk.seed}   params hash: {d['params_hash']} (at {d['quality']})")
    if frame is not None:
        click.echo(f"  at frame {frame}" + (": " + ", ".join(
            f"{k}={v:.6g}" if isinstance(v, float) else f"{k}={v}"
            for k, v in d["values"].items()) if d["values"] else " (nothing is keyframed)"))
    click.echo("  camera: " + ", ".join(f"{k}={v}" for k, v in d["camera"].items()))
    for i, s in enumerate(d["effects"], 1):
        q = f" (quality {s['quality']})" if "quality" in s else ""
        off = " (disabled)" if s.get("enabled") is False else ""
        click.echo((f"  {i}. {s.get('id', s['effect'])}: {s['effect']}{q}{off}"
                    if "id" in s else f"  {i}. {s['effect']}{q}{off}") + _step_origin(s, lk.name))
        if "mask" in s:
            click.echo(f"       mask: {s['mask']}")
        if s.get("missing_passes") == "skip":
            click.echo("       missing passes: skip")
        for k, v in s["params"].items():
            click.echo(f"       {k} = {v!r}")


def _step_origin(shown: dict, name: str) -> str:
    """``look show``'s mark of a step: ``[own]``, ``[inherited from BASE]``, ``[from BASE,
    changed here]``."""
    changed = [c for c in shown.get("changed_in", ()) if c != shown["from"]]
    if shown["from"] == name:
        return "  [own]"
    if not changed:
        return f"  [inherited from {shown['from']}]"
    where = ", ".join("here" if c == name else f"in {c}" for c in changed)
    return f"  [inherited from {shown['from']}, changed {where}]"


@cli.command()
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True)
@pass_options
@colour_options
def probe(file, as_json, colorspace, working_space, view, **kw):
    """Print the channels, windows and passes found in FILE and how they will be read."""
    # lazy: OpenImageIO and the reader are ~0.5 s at start-up
    from clfx.io.probe import format_probe, probe as probe_file

    info = probe_file(file, passes=_pass_options(kw).spec(), colorspace=colorspace,
                      working_space=working_space, view=view)
    click.echo(json.dumps(info, indent=2, default=str) if as_json else format_probe(info))


@cli.command()
@click.argument("query", default="")
@click.option("--limit", default=50, show_default=True)
@click.option("--json", "as_json", is_flag=True)
def lenses(query, limit, as_json):
    """Find real lenses in the lensfun database (for the `lens` effect)."""
    # lazy: the lens database reader is ~40 ms at start-up
    from clfx.fx.lensdb import find_lenses

    rows = find_lenses(query, limit=limit)
    if as_json:
        click.echo(json.dumps(rows, indent=2, default=str))
        return
    if not rows:
        raise ClfxError(f"no lens in the lensfun database matches {query!r}")
    click.echo(lens_table(rows))


LENS_COLUMNS = (("maker", "MAKER"), ("model", "MODEL"), ("focal_range", "FOCAL mm"),
                ("max_aperture", "MAX f/"), ("crop_factor", "CROP"), ("type", "TYPE"),
                ("mounts", "MOUNTS"), ("distortion", "DIST"), ("tca", "TCA"),
                ("vignetting", "VIGN"))
"""``clfx lenses`` columns: (key of `clfx.fx.lensdb.find_lenses`, header)."""


def _lens_cell(key: str, value) -> str:
    if isinstance(value, bool):
        return "yes" if value else "-"
    if key == "focal_range" and isinstance(value, (list, tuple)) and len(value) == 2:
        a, b = value
        return f"{a:g}" if a == b else f"{a:g}-{b:g}"
    if isinstance(value, (list, tuple)):
        return ", ".join(str(v) for v in value)
    if isinstance(value, float):
        return f"{value:g}"
    return "" if value is None else str(value)


def lens_table(rows: list[dict]) -> str:
    """The lenses as a table: a header line, then one aligned row per lens."""
    cols = [(k, h) for k, h in LENS_COLUMNS if any(k in r for r in rows)]
    cells = [[_lens_cell(k, r.get(k)) for k, _ in cols] for r in rows]
    widths = [max([len(h)] + [len(c[i]) for c in cells]) for i, (_, h) in enumerate(cols)]
    fmt = lambda items: "  ".join(v.ljust(w) for v, w in zip(items, widths)).rstrip()  # noqa: E731
    return "\n".join([fmt([h for _, h in cols])] + [fmt(c) for c in cells])


# -- render / apply ------------------------------------------------------------------------
def _pass_options(kw: dict):
    """The pass options of a command's keyword arguments (see ``cli_options.pass_options``)."""
    # lazy: the render stack (device, OpenImageIO, looks) is ~1 s; --help must not wait
    from clfx.pipeline.options import PassOptions

    return PassOptions(**{name: kw[name] for name in PassOptions.names()})


def _render_options(kw: dict):
    """The typed options of ``render`` / ``apply`` from their keyword arguments, with the
    command line (stamped into outputs)."""
    # lazy: the render stack (device, OpenImageIO, looks) is ~1 s; --help must not wait
    from clfx.pipeline.options import PassOptions, RenderOptions

    passes = set(PassOptions.names())
    rest = {k: v for k, v in kw.items() if k not in passes}
    rest["raw_format"] = rest.get("raw_format") or RenderOptions.raw_format   # the default
    return RenderOptions(passes=_pass_options(kw), command=_command_line(), **rest)


def _command_line() -> str:
    """The command line as a shell would take it (stamped as clfx:commandLine)."""
    ctx = click.get_current_context(silent=True)
    args = ctx.meta.get("clfx.argv", []) if ctx is not None else []
    return shlex.join(["clfx", *map(str, args)])


def _check_raw_usage(input_path: str, output_path: str, raw_size, raw_format=None) -> None:
    """'-' as INPUT needs --raw WxH; --raw and --raw-format need a '-': usage errors (exit 2)
    before anything.  '-' as OUTPUT alone takes the frames' size from the first input."""
    if input_path == RAW and not raw_size:
        raise click.UsageError("'-' as INPUT needs --raw WxH, the size of the raw frames on "
                               "stdin (--raw-format says their layout; default gbrpf32le)")
    if RAW not in (input_path, output_path):
        if raw_size:
            raise click.UsageError("--raw WxH is for raw pipes ('-' as INPUT or OUTPUT); "
                                   "INPUT and OUTPUT here are files")
        if raw_format:
            raise click.UsageError("--raw-format is for raw pipes ('-' as INPUT or OUTPUT); "
                                   "INPUT and OUTPUT here are files")


RAW = "-"


@cli.command()
@click.argument("input_path", metavar="INPUT")
@click.argument("output_path", metavar="OUTPUT")
@click.option("--look", "look_name", default=None,
              help="Look name or YAML file  [default: default].")
@click.option("--look-from", "look_from", default=None, metavar="FILE",
              help="Render with the look stamped in FILE (an output of clfx), e.g. to "
                   "re-render a shot from one of its frames.")
@click.option("--set", "assignments", multiple=True, metavar="K=V",
              help="Override: effect.param=value, effect.enabled=false, "
                   "effect.missing_passes=skip, camera.key=value (F:V,F:V keyframes), seed=N.")
@render_options
@click.option("--workers", type=click.IntRange(min=1), default=None, metavar="N",
              help="Render on a local Dask cluster of N processes (one OpenCL device each).")
@click.option("--scheduler", envvar="CLFX_SCHEDULER", default=None, metavar="ADDRESS",
              help="Render on an existing Dask cluster, e.g. tcp://host:8786 (env CLFX_SCHEDULER).")
@click.option("--chunk", type=click.IntRange(min=1), default=1, show_default=True,
              help="Frames per task with --workers/--scheduler.")
@click.option("--fail-fast", is_flag=True,
              help="With --workers/--scheduler: stop at the first failed frame.")
@click.pass_context
def render(ctx, input_path, output_path, look_name, look_from, assignments, workers, scheduler,
           chunk, fail_fast, **kw):
    """Render INPUT (file or sequence pattern like shot.#.exr) through a look to OUTPUT."""
    if look_name and look_from:
        raise click.UsageError("give --look or --look-from, not both")
    _check_raw_usage(input_path, output_path, kw.get("raw_size"), kw.get("raw_format"))
    if workers and ctx.get_parameter_source("scheduler") == click.core.ParameterSource.ENVIRONMENT:
        scheduler = None  # an explicit --workers wins over CLFX_SCHEDULER
    if workers and scheduler:
        raise click.UsageError("give --workers N (a local cluster) or --scheduler ADDRESS "
                               "(an existing one), not both")
    # lazy: the render stack (device, OpenImageIO, looks) is ~1 s; --help must not wait
    from clfx.pipeline.options import ClusterOptions

    scale = ClusterOptions(workers=workers, scheduler=scheduler, chunk=chunk, fail_fast=fail_fast)
    options = _render_options(kw)
    _check_first_frame(input_path, options)
    runtime = None if workers or scheduler else _runtime_soon(ctx)

    # lazy: the render stack (device, OpenImageIO, looks) is ~1 s; --help must not wait
    from clfx.api import load_look, look_from_stamp, stamped_quality

    lk = look_name or "default"
    if look_from:
        stamped = stamped_quality(look_from)      # the level FILE was rendered at, read once
        if not options.quality:
            options = replace(options, quality=stamped)
        # no stamp: no step took the render's level, nothing to relevel
        lk = look_from_stamp(look_from, relevel=bool(options.quality) and stamped is not None,
                             level=stamped)
    lk = load_look(lk, set=assignments)
    _run_batch(ctx, lk, input_path, output_path, options, runtime,
               scale if runtime is None else None)


@cli.group(cls=ClfxGroup)
def farm():
    """Job descriptions for render farms (docs/scaling.md)."""


@farm.command("openjd")
@click.argument("input_path", metavar="INPUT")
@click.argument("output_path", metavar="OUTPUT")
@click.argument("render_args", nargs=-1, metavar="[-- RENDER_OPTION...]")
@click.option("--look", "look_name", default="default", show_default=True)
@click.option("--set", "assignments", multiple=True, metavar="K=V")
@click.option("--frames", default=None, metavar="SPEC", callback=check_frames,
              help="Default: every input frame on disk.")
@click.option("--chunk", type=click.IntRange(min=1), default=10, show_default=True,
              help="Frames per task.")
@click.option("--quality", type=click.Choice(["draft", "preview", "final", "reference"]), default=None)
@click.option("--name", default=None, help="Job name.")
@click.option("--clfx", "clfx_command", default="clfx", show_default=True,
              help="The clfx command on the farm's workers.")
@click.option("--task-chunking/--explicit-chunks", default=True, show_default=True,
              help="CHUNK[INT] (TASK_CHUNKING extension) or a list of chunk ranges.")
@click.option("--path-params", is_flag=True,
              help="Folders as PATH parameters (path mapping, job attachments), given at submission.")
def farm_openjd(input_path, output_path, render_args, look_name, assignments, frames, chunk,
                quality, name, clfx_command, task_chunking, path_params):
    """Print an Open Job Description template whose tasks run `clfx render` on chunks."""
    # lazy: the render stack (device, OpenImageIO, looks) is ~1 s; --help must not wait
    from clfx.farm import openjd_template, openjd_yaml
    from clfx.io.sequence import Pattern, hash_notice

    _check_render_args(render_args)
    for path in dict.fromkeys((input_path, output_path)):   # as each task will say it
        message = hash_notice(Pattern.parse(path))
        if message:
            click.echo(f"clfx: warning: {message}", err=True)
    click.echo(openjd_yaml(openjd_template(
        input_path, output_path, look=look_name, assignments=assignments, frames=frames,
        chunk=chunk, quality=quality, render_args=render_args, name=name, clfx=clfx_command,
        task_chunking=task_chunking, path_params=path_params)), nl=False)


@cli.command()
@click.argument("effect")
@click.argument("input_path", metavar="INPUT")
@click.argument("output_path", metavar="OUTPUT")
@click.argument("assignments", nargs=-1, metavar="[PARAM=VALUE]...")
@render_options
@click.pass_context
def apply(ctx, effect, input_path, output_path, assignments, **kw):
    """Apply one EFFECT to INPUT with PARAM=VALUE settings (camera.key=value too)."""
    _check_raw_usage(input_path, output_path, kw.get("raw_size"), kw.get("raw_format"))
    options = _render_options(kw)
    _check_first_frame(input_path, options)
    runtime = _runtime_soon(ctx)
    # lazy: the render stack (device, OpenImageIO, looks) is ~1 s; --help must not wait
    from clfx.pipeline.presets import single_effect_look

    lk = single_effect_look(effect, list(assignments))
    _run_batch(ctx, lk, input_path, output_path, options, runtime)


def _run_batch(ctx, lk, input_path, output_path, options, runtime, scale=None):
    """``clfx render`` / ``apply``: `clfx.api.render`, with progress on a terminal."""
    # lazy: the render stack (device, OpenImageIO, looks) is ~1 s; --help must not wait
    from clfx.api import render as render_api

    verbosity = ctx.obj.get("verbosity", 1)
    _cold_steps.append(max(1, len(lk.active_steps())))
    show = verbosity > 0 and sys.stderr.isatty() and not options.as_json
    with _progress(show) as on_frame:
        render_api(input_path, output_path, lk, options=options, verbosity=verbosity,
                   on_frame=on_frame, runtime=runtime, device=ctx.obj.get("device"),
                   distributed=scale)


class _Progress:
    """Frames done/total, frames per second, elapsed time and ETA on stderr (rich), only
    on a terminal and never with -q: `clfx.api.render`'s ``on_frame`` (in this process or
    on a cluster, where frames count as they finish).  Elapsed time counts from when the
    render was asked for (device set-up included); frames per second from when frames
    start rendering (`timing`: after a cluster's start-up), as the summary's do (told no
    time, from the first frame's start: it began about its own time ago).  Lines said
    meanwhile are not wrapped; `close` (before the summary) takes the bar away."""

    def __init__(self, clock=None, console=None):
        # lazy: rich is ~0.1 s at start-up; only the progress bar needs it
        from rich.console import Console
        from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                                   TimeRemainingColumn)

        self.clock = clock or time.perf_counter
        self.bar = Progress(TextColumn("clfx"), BarColumn(), MofNCompleteColumn(),
                            TextColumn("frames  {task.fields[fps]}"),
                            TextColumn("{task.fields[elapsed]}"),
                            TextColumn("ETA"), TimeRemainingColumn(),
                            console=console or Console(file=sys.stderr, soft_wrap=True),
                            transient=True)
        self.task = None
        self.t_start = self.clock()
        self.t0 = None
        self.closed = False

    def timing(self, t0: float) -> None:
        """Frames render from ``t0`` (the clock's time) on."""
        self.t0 = t0

    def fps(self, done: int) -> float:
        """Frames per second so far (since `timing`'s ``t0``, else since the bar began)."""
        return done / max(self.clock() - (self.t_start if self.t0 is None else self.t0), 1e-9)

    def __call__(self, done: int, total: int | None, report) -> None:
        if self.closed:
            return
        if self.task is None:
            if self.t0 is None:      # no timing: the first frame began about its own time ago
                took = (report.total_ms + report.read_ms) / 1e3 if report is not None else 0.0
                self.t0 = max(self.t_start, self.clock() - max(took, 1e-3))
            self.bar.start()
            self.task = self.bar.add_task("render", total=total, fps="", elapsed="")
        self.bar.update(self.task, completed=done, total=total, fps=f"{self.fps(done):.2f} fps",
                        elapsed=_clock_text(self.clock() - self.t_start))

    def close(self) -> None:
        if self.task is not None and not self.closed:
            self.bar.stop()
        self.closed = True


def _clock_text(seconds: float) -> str:
    """``m:ss``, or ``h:mm:ss`` from an hour."""
    s = round(seconds)
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


@contextlib.contextmanager
def _progress(show: bool):
    if not show:
        yield None
        return
    bar = _Progress()
    try:
        yield bar
    finally:
        bar.close()


@cli.command()
@click.argument("outdir", default="clfx-demo", required=False)
@click.option("--frames", "count", type=click.IntRange(min=1), default=24, show_default=True,
              help="Number of frames.")
@click.option("--size", default="640x360", show_default=True, help="WxH.")
@click.option("--look", "look_name", default="default", show_default=True)
@quality_option
@click.option("-y", "--overwrite", is_flag=True,
              help="Replace files of an earlier demo in OUTDIR (default: refuse, like render).")
@click.option("--explain", is_flag=True)
@click.option("--json", "as_json", is_flag=True)
@click.pass_context
def demo(ctx, outdir, count, size, look_name, quality, overwrite, explain, as_json):
    """Render the built-in procedural HDR scene through a look: EXRs, PNG previews and a
    contact sheet in OUTDIR.  Needs no input files."""
    # lazy: the render stack (device, OpenImageIO, looks) is ~1 s; --help must not wait
    from clfx.api import load_look
    from clfx.demo import run_demo

    w, h = _parse_size(size)
    _cold_steps.append(max(1, len(load_look(look_name).active_steps())))   # the notice's ~N s
    run_demo(_runtime(ctx), outdir, count=count, width=w, height=h, look_name=look_name,
             quality=quality, overwrite=overwrite, explain=explain, as_json=as_json,
             verbosity=ctx.obj.get("verbosity", 1))


@cli.command()
@click.argument("outdir", default="clfx-gallery", required=False)
@click.option("--width", default=640, show_default=True, type=click.IntRange(min=1),
              help="Width the images are scaled to (pixels, at least 1).")
@click.option("--only", default=None, metavar="A,B", callback=lambda c, p, v: _gallery_names(v),
              help="Only these effects and looks.")
@quality_option
@click.option("-y", "--overwrite", is_flag=True,
              help="Replace files of an earlier gallery in OUTDIR (default: refuse, like demo).")
@click.pass_context
def gallery(ctx, outdir, width, only, quality, overwrite):
    """Every effect and built-in look on the demo scene, CandleGlass.exr and Desk.exr: a
    labelled before/after contact sheet per image in OUTDIR."""
    # lazy: the render stack (device, OpenImageIO, looks) is ~1 s; --help must not wait
    from clfx.gallery import run_gallery

    run_gallery(_runtime(ctx), outdir, width=width, quality=quality, only=only,
                overwrite=overwrite, verbosity=ctx.obj.get("verbosity", 1))


def _gallery_names(value: str | None) -> set[str] | None:
    """``--only A,B``: names of gallery tiles (effects, their variants, built-in looks); an
    unknown one is a usage error naming the closest, before anything renders."""
    if value is None:
        return None
    # lazy: the render stack (device, OpenImageIO, looks) is ~1 s; --help must not wait
    from clfx.gallery import VARIANTS
    from clfx.pipeline.presets import available_looks
    from clfx.plugins import discover

    known = set(discover()) | set(VARIANTS) | {n for n, (origin, _) in available_looks().items()
                                              if origin == "built-in"}
    names = {n.strip() for n in value.split(",")}
    _check_names(names, known, "effect or look")
    return names


def _check_names(names, known, what: str) -> None:
    """A usage error for the first of ``names`` not in ``known``, naming the closest."""
    for name in sorted(names):
        if name not in known:
            close = difflib.get_close_matches(name, sorted(known), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise click.BadParameter(f"unknown {what} {name!r}{hint} (known: "
                                     f"{', '.join(sorted(known))})")


def _bench_looks(ctx, param, value):
    """``--looks A,B``: looks the bench can load (names or files), or ``none``; an unknown
    one is a usage error before anything is measured."""
    if value is None or value == "none":
        return value
    # lazy: the render stack (device, OpenImageIO, looks) is ~1 s; --help must not wait
    from clfx.pipeline.presets import find_look

    for name in value.split(","):
        try:
            find_look(name)
        except PresetError as exc:
            raise click.BadParameter(" ".join(str(exc).split())) from None
    return value


@cli.command()
@click.option("--effects", default=None, metavar="A,B",
              help="Effects to measure (default: all; 'none' to skip).")
@click.option("--looks", default=None, metavar="A,B", callback=_bench_looks,
              help="Looks to measure (default: every built-in look; 'none' to skip).")
@click.option("--size", default="1920x1080", show_default=True, help="WxH of the bench frames.")
@click.option("--repeat", default=5, show_default=True, help="Warm runs per measurement (median; at least 25 for operations under 0.1 s).")
@click.option("--sequence-frames", default=8, show_default=True,
              help="Frames for the sequence-throughput measurement (0 to skip).")
@click.option("--json", "as_json", is_flag=True, help="Print the results as JSON on stdout.")
@click.option("--plot", "plot_path", default=None, metavar="FILE", help="Pareto plot PNG (matplotlib).")
@click.option("--markdown", "md_path", default=None, metavar="FILE", help="Write the tables as markdown.")
@click.pass_context
def bench(ctx, effects, looks, size, repeat, sequence_frames, as_json, plot_path, md_path):
    """What accuracy costs in time: every effect at every quality level against its reference
    (with OpenCV/SciPy peers), whole looks, sequence throughput, and scene-analysis skipping."""
    # lazy: the bench (scenes, cases, plots) is ~1 s at start-up
    from clfx.bench.plots import check_plot_path, pareto_plot
    from clfx.bench.report import markdown
    from clfx.bench.runner import run_bench

    # lazy: limits reads CLFX_MAX_PIXELS at import: a bad value is main's one error line
    from clfx.core.limits import check_pixels

    w, h = _parse_size(size)
    check_pixels(w, h, "--size")
    if plot_path:
        check_plot_path(plot_path)
    for option, path in (("--markdown", md_path), ("--plot", plot_path)):
        if path:
            _check_writable(path, option)
    look_list = None if looks is None else ([] if looks == "none" else looks.split(","))
    verbose = ctx.obj.get("verbosity", 1) > 0
    effect_list = None if effects is None else ([] if effects == "none" else effects.split(","))
    results = run_bench(_runtime(ctx), effects=effect_list,
                        looks=look_list, width=w, height=h, repeat=max(1, repeat),
                        sequence_frames=sequence_frames,
                        log=(lambda m: click.echo(m, err=True)) if verbose else (lambda m: None))
    table = markdown(results)
    try:
        if md_path:
            with open(md_path, "w") as f:
                f.write(table)
        if plot_path:
            pareto_plot(results, plot_path)
    except OSError as exc:
        raise ClfxError(f"cannot write {exc.filename or md_path}: {exc.strerror or exc}") \
            from None
    if as_json:
        click.echo(json.dumps(results, default=lambda o: None if isinstance(o, float) and not math.isfinite(o) else str(o)))
    else:
        click.echo(table)


@cli.command()
@click.option("--looks", default="all", show_default=True, metavar="A,B|all",
              help="Looks (names or files); all: every look `clfx looks` lists.")
@click.option("--quality", "levels", default="final", show_default=True,
              metavar="LEVEL,...|all", help="Quality levels: draft, preview, final, reference.")
@click.option("--size", default="640x360", show_default=True,
              help="WxH of the frame rendered: the plates' size also warms PoCL's "
                   "work-group code for it.")
@click.pass_context
def prebuild(ctx, looks, levels, size):
    """Compile the kernels of looks at quality levels into the kernel cache, ahead of renders
    (e.g. when a farm node's image is built): renders one demo frame through each."""
    # lazy: the render stack (device, OpenImageIO, looks) is ~1 s; --help must not wait
    from clfx.device import runtime
    from clfx.pipeline.presets import available_looks
    from clfx.prebuild import levels_of, prebuild as run_prebuild

    w, h = _parse_size(size)
    try:
        level_list = levels_of(levels)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--quality") from None
    names = list(available_looks()) if looks == "all" else looks.split(",")
    _bench_looks(ctx, None, ",".join(names))
    rt = _runtime(ctx)
    runtime.cold_build_notice = None      # compiling is what it is asked to do: said below
    where = rt.kernel_cache_dir or "the OpenCL driver's cache"
    click.echo(f"clfx prebuild: {len(names)} look(s) at {', '.join(level_list)}, {w}x{h}, "
               f"on {rt.description}, into {where}")
    t0 = time.perf_counter()
    rows = run_prebuild(rt, names, level_list, w, h, log=click.echo)
    total = time.perf_counter() - t0
    click.echo(f"clfx prebuild: {sum(r['compiled'] for r in rows)} program(s) compiled, "
               f"{sum(r['programs'] - r['compiled'] for r in rows)} already cached, "
               f"in {total:.1f} s")


def _check_writable(path: str, option: str) -> None:
    """Refuse, before a long run, an output file that cannot take what it will be given: a
    folder, a FIFO (it would block), a missing or read-only folder, a device that refuses a
    byte (/dev/full) or a file system without a free block."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        mode = None
    except OSError as exc:
        raise ClfxError(f"cannot write {option} {path}: {exc.strerror}") from None
    if mode is not None and not (stat.S_ISREG(mode) or stat.S_ISCHR(mode)):
        raise ClfxError(f"cannot write {option} {path}: "
                        f"{'a folder' if stat.S_ISDIR(mode) else 'not a regular file'}")
    try:
        if mode is not None and stat.S_ISCHR(mode):
            with open(path, "wb", buffering=0) as f:
                f.write(b"\n")                   # /dev/null takes it, /dev/full does not
            return
        folder = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(folder):
            raise FileNotFoundError(2, f"no folder {folder}")
        if not os.access(folder, os.W_OK) or (mode is not None and not os.access(path, os.W_OK)):
            raise PermissionError(13, "Permission denied")
        if os.statvfs(folder).f_bavail == 0:
            raise OSError(28, "No space left on device")
    except OSError as exc:
        raise ClfxError(f"cannot write {option} {path}: {exc.strerror or exc}") from None


def _parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
        if w < 1 or h < 1:
            raise ValueError
        return w, h
    except ValueError:
        raise click.BadParameter(f"{text!r} is not WxH (e.g. 1920x1080)") from None


SIGNAL_GRACE_S = 0.5
"""After SIGTERM or SIGINT, how long the main thread has to stop by itself (its handler runs
between Python statements) before the process ends regardless: a thread that hears the
signal removes the temp files being written and exits 143 / 130 (the main thread may be
inside one long call: an FFT plan, a device wait, numpy on a large array)."""


def _watch_signals() -> None:
    """Hear SIGTERM / SIGINT on a thread (Python's wakeup descriptor) whatever the main
    thread is doing, and end the process `SIGNAL_GRACE_S` later if it is still running."""
    try:
        r, w = os.pipe()
        os.set_blocking(w, False)
        signal.set_wakeup_fd(w, warn_on_full_buffer=False)
    except (OSError, ValueError):       # not the main thread (embedded): the handlers alone
        return

    def watch():
        while True:
            try:
                data = os.read(r, 64)
            except OSError:
                return
            for signum in data:
                if signum in (signal.SIGTERM, signal.SIGINT):
                    time.sleep(SIGNAL_GRACE_S)
                    write = sys.modules.get("clfx.io.write")
                    if write is not None:
                        write.abandon_writes()
                    term = signum == signal.SIGTERM
                    with contextlib.suppress(Exception):
                        if not _ENDED:      # else the main thread said it (`_say_end`)
                            os.write(2, b"clfx: terminated\n" if term else
                                     b"clfx: interrupted\n")
                    os._exit(EXIT_TERMINATED if term else EXIT_INTERRUPTED)

    threading.Thread(target=watch, name="clfx-signals", daemon=True).start()


def main(argv=None):
    """Entry point: ClfxError -> one line and exit 1; interrupts -> no partial files."""
    signal.signal(signal.SIGTERM, _on_sigterm)
    _watch_signals()
    saved = sys.stdin, sys.stdout, sys.stderr
    sys.stdin = sys.stdin if sys.stdin is not None else _GuardedStream(None, "stdin")
    sys.stdout = _GuardedStream(sys.stdout, "stdout")
    if sys.stderr is None:  # messages to a closed stderr go nowhere, not to stdout
        sys.stderr = open(os.devnull, "w")  # noqa: SIM115 (kept open for the process)
    try:
        _main(argv)
    finally:
        sys.stdin, sys.stdout, sys.stderr = saved


def _main(argv):
    try:
        cli.main(args=argv, prog_name="clfx", standalone_mode=False)
        sys.stdout.flush()  # a failed write still buffered is an error too
    except click.exceptions.Abort:
        _say_end("clfx: interrupted")
        sys.exit(EXIT_INTERRUPTED)
    except click.UsageError as exc:          # before a subcommand runs (clfx --bogus)
        _one_line_usage(exc).show()
        sys.exit(exc.exit_code)
    except click.ClickException as exc:
        exc.show()
        sys.exit(exc.exit_code)
    except ClfxError as exc:  # raised outside a subcommand (e.g. while parsing)
        ClfxClickError(" ".join(str(exc).split())).show()
        sys.exit(1)
    except KeyboardInterrupt:
        _say_end("clfx: interrupted")
        sys.exit(EXIT_INTERRUPTED)
    except _Terminated:
        _say_end("clfx: terminated")
        sys.exit(EXIT_TERMINATED)
    except BrokenPipeError:
        _to_devnull(sys.stdout)
        sys.exit(1)
    sys.exit(0)


if __name__ == "__main__":  # pragma: no cover
    main()
