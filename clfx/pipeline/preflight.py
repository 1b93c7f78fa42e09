"""The checks before any frame: everything that can be checked is checked before the first
frame is read (`Preflight.prepare`, run by `clfx.pipeline.batch.Batch.prepare`): the look,
the input frames (missing ones named), the output folder, existing outputs, inputs that
would be overwritten, the --log file; raw pipes as far as a stream of unknown length can
be.  What passes makes the batch's `clfx.pipeline.plan.BatchPlan`.  `check_first_frame`
refuses an oversized first frame from its header before ``clfx render`` sets up the device."""
from __future__ import annotations

import os
import stat
import sys
from dataclasses import replace

from clfx.core.errors import ClfxError, ImageIOError, SequenceError, option
from clfx.io.colour import check_config, config_file
from clfx.io.probe import header_attribute, probe as probe_file
from clfx.io.raw import check_format, check_stream_size, parse_size
from clfx.io.read import beauty_geometry
from clfx.io.sequence import (Pattern, check_input_file, compact, hash_notice, output_path,
                              parse_frames, resolve_inputs)
from clfx.io.write import OutputExistsError, check_output_format, sweep_stale_temps
from clfx.pipeline.look import Look
from clfx.pipeline.masks import check_mask
from clfx.pipeline.options import RAW, RenderOptions
from clfx.pipeline.plan import BatchPlan, Job
from clfx.pipeline.presets import find_lens


def look_files(look: Look) -> list[tuple[str, str]]:
    """(``effect.param``, path) of every file a step reads (a PathParam): inputs of the render."""
    return [(f"{s.id}.{p.name}", getattr(s.params, p.name)) for s in look.steps
            for p in s.plugin.descriptor.params if p.kind == "path" and getattr(s.params, p.name)]


def lens_files(look: Look) -> list[tuple[str, str]]:
    """(``effect.param``, file) of every lens prescription an enabled step reads (its
    plugin's `clfx.host.Plugin.lens_refs`, the lenses `clfx.io.lenses.resolve` reads)."""
    return [(f"{s.id}.{param}", str(find_lens(value))) for s in look.steps if s.enabled
            for param, kind, value in s.plugin.lens_refs(s.params) if kind == "prescription"]


def _inode(path: str) -> tuple[int, int] | None:
    """(device, inode) of the file at ``path``, None if there is none."""
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return st.st_dev, st.st_ino


def first_frame_geometry(path: str):
    """The data window, display window and pixel aspect of the frame `read_frame` would take
    from ``path``, from its headers; refused (`ImageIOError`, the reader's message) when a
    window exceeds the limits of `clfx.core.limits`.  A render checks its first frame so
    before anything is set up for it (the device, the first read, the maps)."""
    return beauty_geometry(path, check=True)


def check_first_frame(input_path: str, options: RenderOptions) -> None:
    """Refuse the first frame of ``input_path`` (a file or a sequence, ``options.frames``)
    whose windows exceed the pixel limits, from its header: ``clfx render`` calls this before
    it starts setting up the device.  Missing frames and everything else are left to
    `Batch.prepare`, which checks the first frame it will render again."""
    if input_path == RAW:
        return

    try:
        frames = parse_frames(options.frames) if options.frames else None
        inputs = resolve_inputs(Pattern.parse(input_path), frames, skip_missing=True)
    except SequenceError:
        return              # said by Batch.prepare, in its order of checks
    if inputs and not options.skip_existing:   # with --skip-existing: the first one rendered
        first_frame_geometry(inputs[0][1])


def check_output_folder(output: str) -> None:
    """The folder of ``output`` exists (created now if need be) and can be written."""
    folder = os.path.dirname(os.path.abspath(output))
    if not os.path.isdir(folder):
        try:
            os.makedirs(folder, exist_ok=True)
        except OSError as exc:
            raise ImageIOError(f"cannot create output folder {folder}: {exc.strerror}") from exc
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ImageIOError(f"output folder {folder} is not writable")



class Preflight:
    """The checks of a `clfx.pipeline.batch.Batch` before any frame is read, mixed into it:
    they read its ``look``, ``input_path``, ``output_path``, ``options`` and ``reporter``,
    and fill in its ``plan``, ``skipped_existing``, ``kept_other``, ``look_files`` and
    ``mask_files``."""

    # -- checks -------------------------------------------------------------------------
    def prepare(self) -> None:
        """Resolve frames and outputs; raise before any pixel is read if anything is wrong;
        make the `plan`."""
        o = self.options
        check_config()      # a FIFO or broken $OCIO: refused before anything reads a frame
        if self.input_path == RAW:
            given = [option(f"--{n}") for n in ("depth", "velocity") if getattr(o, f"{n}_path")]
            if given:       # raw frames on stdin are RGB only: no pass, no frame name to match
                raise ClfxError(f"{' and '.join(given)} cannot go with raw frames on stdin ('-': "
                                f"RGB only); render EXR files with "
                                f"{'those passes' if len(given) > 1 else 'that pass'} instead")
            self._prepare_raw()
            return
        raw_out = self.output_path == RAW        # files to a raw stream on stdout
        frames = parse_frames(o.frames) if o.frames else None
        pin = Pattern.parse(self.input_path)
        pout = Pattern.parse(self.output_path)
        if pin.is_sequence and not pout.is_sequence and not raw_out:
            raise SequenceError(f"input {self.input_path} is a sequence but output "
                                f"{self.output_path} has no frame token (use e.g. out.#.exr)")
        self._say_padding(pin, pout, *(Pattern.parse(p) for p in (o.depth_path, o.velocity_path)
                                       if p))
        inputs = resolve_inputs(pin, frames, skip_missing=o.skip_missing)
        if not inputs:
            raise SequenceError(f"no input frames found for {self.input_path}")
        if frames is None and pin.is_sequence:
            self._say_gaps([f for f, _ in inputs])
        aux = {}
        for name in ("depth", "velocity"):
            path = getattr(o, f"{name}_path")
            if path:
                pat = Pattern.parse(path)
                found = dict(resolve_inputs(pat, [f for f, _ in inputs] if pat.is_sequence else None,
                                            skip_missing=False))
                aux[name] = (pat, found)
        jobs = []
        for frame, path in inputs:
            out = output_path(pout, frame) if pout.is_sequence and not raw_out else \
                self.output_path
            passes = {name: found[frame] if pat.is_sequence else next(iter(found.values()))
                      for name, (pat, found) in aux.items()}
            jobs.append(Job(frame, path, out, **passes))
        self.look_files = [check_input_file(p, what) for what, p in look_files(self.look)]
        self._check_masks(jobs)
        self.plan = BatchPlan.of(self.look, o, reads=self._reads(jobs))   # what is read: checked
        self.reporter.stamped(self.plan.look.params_hash(), self.plan.quality)
        if raw_out:
            check_format(o.raw_format)
            self._say_no_overscan()
        else:
            self._check_outputs(jobs)
        self._check_log(jobs)
        jobs = tuple(j for j in jobs if j.frame not in self.skipped_existing)
        size = None
        if jobs:   # before anything is set up for it (device, first read, maps)
            _, display, _ = first_frame_geometry(jobs[0].input)
            size = (display.width, display.height)
        if raw_out:
            size = self._raw_out_size(jobs[0].input, size)
        self.plan = replace(self.plan, jobs=jobs, raw_out=size if raw_out else None,
                            passes=o.passes.spec(self._radial_depth_focal_px(jobs)))

    def _say_padding(self, *patterns) -> None:
        """One line for each pattern whose ``#`` count differs from Nuke's meaning
        (`clfx.io.sequence.hash_notice`: ``shot.####.exr`` is 16 digits here)."""
        for pattern in patterns:
            message = hash_notice(pattern)
            if message:
                self.reporter.assumed(message, f"padding:{pattern.text}")

    def _say_no_overscan(self) -> None:
        """One line when ``--keep-overscan`` cannot hold: raw frames on stdout are the
        frame's size (a raw input's, a file's display window)."""
        if self.options.keep_overscan:
            self.reporter.assumed(f"{option('--keep-overscan')} ignored: raw frames on stdout "
                                  f"hold the frame only (light spread past it is cropped)",
                                  "overscan")

    def _raw_out_size(self, first: str, size: tuple[int, int]) -> tuple[int, int]:
        """The size of the raw frames written to stdout: the first input's display window,
        which ``--raw WxH``, when given, must match; said once on stderr (ffmpeg's ``-s``)."""
        if self.options.raw_size:
            want = parse_size(self.options.raw_size)
            if want != size:
                raise SequenceError(f"{option('--raw', self.options.raw_size)}: {first} has a "
                                    f"{size[0]}x{size[1]} display window (the raw frames' size)")
        fmt = self.options.raw_format
        self.reporter.notice(f"writing raw {fmt} frames of {size[0]}x{size[1]} to stdout "
                             f"(ffmpeg -f rawvideo -pix_fmt {fmt} -s {size[0]}x{size[1]} -i -)",
                             "raw")
        return size

    def _radial_depth_focal_px(self, jobs) -> float | None:
        """Focal length in pixels for --depth-mode distance, from the look's camera block and
        the first input's display width (square pixels assumed, as the camera block does)."""
        p = self.options.passes
        if p.depth_mode != "distance" or p.focal_length_px or not jobs:
            return None

        info = probe_file(jobs[0].input)
        part = info["beauty"]["part"] if info["beauty"] else 0   # pass-only: read refuses it
        width = info["parts"][part]["display_window"]["width"]
        return self.look.camera.focal_length_px(width)

    def _say_gaps(self, found: list[int]) -> None:
        """One notice when the frames found on disk (no --frames) skip some: a missing frame
        is not rendered, and the output has the same hole.  Evenly stepped frames (every
        other frame on disk) are a sequence, not a gap."""
        steps = {b - a for a, b in zip(found, found[1:])}
        if len(steps) < 2:
            return
        step = min(steps)
        gaps = [(a + step, b - step) for a, b in zip(found, found[1:]) if b - a > step]
        shown = ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in gaps[:5])
        more = f" and {len(gaps) - 5} more" if len(gaps) > 5 else ""
        self.reporter.notice(f"{self.input_path} has gaps on disk: frame(s) {shown}{more} "
                             f"missing between {found[0]} and {found[-1]}; rendering the "
                             f"{len(found)} there (--frames {found[0]}-{found[-1]} would "
                             f"refuse)", "gaps")

    def _check_masks(self, jobs: list[Job]) -> None:
        """Every masked step's mask can be made: its files exist, its channel, layer and
        names are in the first frame's header (`clfx.pipeline.masks.check_mask`)."""
        files: set[str] = set()
        for step, mask in self.look.masks():
            files.update(check_mask(mask, jobs[0].input, [j.frame for j in jobs],
                                    f"effect {step.id!r}", notify=self.reporter.assumed))
        self.mask_files = sorted(files)

    def _reads(self, jobs: list[Job]) -> list[tuple[str, str]]:
        """(role, path) of every file this render reads: the frames and their depth and
        velocity files, the files the look was read from (its YAML and its base looks', or
        the output of ``--look-from``), mask files, files effects read (kernel images, lens
        prescriptions) and the OCIO config.  The one list every output and ``--log`` is
        checked against (`_check_outputs`, `_check_log`, the writer's ``protect``)."""
        reads = [(role, p) for j in jobs for role, p in
                 (("input", j.input), ("--depth", j.depth), ("--velocity", j.velocity)) if p]
        reads += [("look", p) for p in self.look.files]
        reads += [("mask", p) for p in self.mask_files]
        reads += look_files(self.look) + lens_files(self.look)
        ocio = config_file()
        if ocio:
            reads.append(("$OCIO", ocio))
        return reads

    def read_paths(self) -> list[str]:
        """The paths of `reads` (what the writer protects)."""
        return [p for _, p in self.reads]

    def _read_by(self, path: str) -> str | None:
        """The role of the file ``path`` (the same file, through a symbolic or hard link) if
        the render reads it, else None."""
        if self._read_index is None or self._read_index[0] is not self.reads:
            by_path, by_inode = {}, {}
            for role, p in reversed(self.reads):     # the first role given wins
                by_path[os.path.realpath(p)] = role
                key = _inode(p)
                if key is not None:
                    by_inode[key] = role
            self._read_index = (self.reads, by_path, by_inode)
        _, by_path, by_inode = self._read_index
        role = by_path.get(os.path.realpath(path))
        key = _inode(path)
        return role if role is not None or key is None else by_inode.get(key)

    def _check_log(self, jobs: list[Job] | None = None) -> None:
        """The --log file is none of the render's inputs or outputs, is a regular file (or a
        device such as /dev/null; a FIFO would block), and can be written (created now,
        empty)."""
        path = self.options.log_path
        if not path:
            return
        role = self._read_by(path)
        if role is not None:
            raise ImageIOError(f"{option('--log')} {path} is an input of this render ({role}); "
                               f"clfx never overwrites its inputs")
        real = os.path.realpath(path)
        if any(os.path.realpath(j.output) == real for j in (jobs or [])):
            raise ImageIOError(f"{option('--log')} {path} is an output of this render")
        try:
            mode = os.stat(path).st_mode
        except FileNotFoundError:
            mode = None
        except OSError as exc:
            raise ImageIOError(f"cannot write {option('--log')} {path}: {exc.strerror}") from None
        if mode is not None and not (stat.S_ISREG(mode) or stat.S_ISCHR(mode)):
            kind = "a folder" if stat.S_ISDIR(mode) else \
                "not a regular file (a FIFO)" if stat.S_ISFIFO(mode) else "not a regular file"
            raise ImageIOError(f"cannot write {option('--log')} {path}: {kind}")
        try:
            with open(path, "w", encoding="utf-8"):
                pass
        except OSError as exc:
            raise ImageIOError(f"cannot write {option('--log')} {path}: {exc.strerror}") from None

    def _check_kept(self, job: Job) -> None:
        """Note a frame --skip-existing keeps that another look or other parameters rendered
        (its stamped ``clfx:paramsHash`` differs from this look's, or it has none)."""
        try:
            stamped = header_attribute(job.output, "clfx:paramsHash")
            name = header_attribute(job.output, "clfx:look") if stamped else None
        except ClfxError:
            stamped = name = None               # unreadable: its render failed half-way?
        if stamped != self.reporter.params_hash:    # the one this render stamps (`prepare`)
            self.kept_other.append((job.frame, name))

    def _kept_other_warning(self) -> str | None:
        """One line for the frames kept from another look (`_check_kept`), or None."""
        if not self.kept_other:
            return None

        names = sorted({n or "no clfx stamp" for _, n in self.kept_other})
        return (f"clfx: warning: --skip-existing keeps frame(s) "
                f"{compact(f for f, _ in self.kept_other)} rendered with another look or other "
                f"parameters ({', '.join(map(repr, names))}; this render: {self.look.name!r}); "
                f"use --overwrite to render them again")

    def _check_outputs(self, jobs: list[Job]) -> None:
        outs = [j.output for j in jobs]
        if len(set(outs)) != len(outs):
            raise SequenceError(f"several frames would write the same output {outs[0]} "
                                f"(add a frame token such as # to the output)")
        for j in jobs:          # first: an output that names a file the render reads
            role = self._read_by(j.output)
            if role is not None:
                what = "" if role == "input" else f" ({role})"
                raise ImageIOError(f"output {j.output} is an input of this render{what}; clfx "
                                   f"never overwrites its inputs")
        check_output_format(outs[0], self.options.out_bit_depth(),
                            self.options.compression)    # not after the first render
        check_output_folder(outs[0])
        if self.options.skip_existing:
            sweep_stale_temps(outs)   # temp files of killed runs (their process is gone)
        for j in jobs:
            if os.path.lexists(j.output):   # a dangling symlink counts
                if self.options.skip_existing:
                    self.skipped_existing.append(j.frame)
                    self._check_kept(j)
                elif not self.options.overwrite:
                    raise OutputExistsError(f"output {j.output} exists (use {option('--overwrite')} "
                                            f"to replace it, or {option('--skip-existing')} to "
                                            f"resume)")


    def _prepare_raw(self) -> None:
        """Raw frames on stdin, to stdout or to a file sequence: checked as far as a stream
        of unknown length can be before it is read."""
        o = self.options

        check_format(o.raw_format)
        if not o.raw_size:
            raise SequenceError(f"'-' as INPUT needs {option('--raw', 'WxH')}, the size of the "
                                f"raw frames on stdin ({o.raw_format}, as ffmpeg's -f rawvideo "
                                f"-pix_fmt {o.raw_format})")
        raw_size = parse_size(o.raw_size)  # two positive whole numbers within the pixel limit
        for clip, effects in self.look.required_clips().items():
            raise SequenceError(f"effect {effects[0]!r} needs a {clip} pass, which raw pipes "
                                f"do not carry ({option('--set', f'{effects[0]}.enabled=false')} drops it, "
                                f"{option('--set', f'{effects[0]}.missing_passes=skip')} skips it)")
        for step, mask in self.look.masks():
            if not mask.file:
                raise SequenceError(f"effect {step.id!r} is masked by a channel of the frame "
                                    "and raw pipes carry colour only (use a mask file:)")
        check_stream_size(sys.stdin.buffer, raw_size, o.raw_format)
        self.look_files = [p for _, p in look_files(self.look)]
        self.mask_files = sorted({f for _, m in self.look.masks() for f in [m.file] if f})
        self.plan = BatchPlan.of(self.look, o, reads=self._reads([]), raw_size=raw_size,
                                 raw_out=raw_size if self.output_path == RAW else None)
        if self.output_path != RAW:
            self._check_raw_outputs()
        else:
            self._say_no_overscan()
        self.reporter.stamped(self.plan.look.params_hash(), self.plan.quality)
        self._check_log()

    def _check_raw_outputs(self) -> None:
        """A raw input's file outputs: a sequence pattern (a stream holds any number of
        frames) in a writable folder and format; outputs already on disk (of ``--frames``,
        else any frame of the pattern) are refused unless overwritten or skipped, and none
        is a file the render reads."""
        o = self.options
        pout = Pattern.parse(self.output_path)
        if not pout.is_sequence:
            raise SequenceError(f"output {self.output_path} has no frame token: raw frames on "
                                f"stdin are a sequence (use e.g. out.#.exr)")
        self._say_padding(pout)
        check_output_folder(self.output_path)
        check_output_format(self.output_path, o.out_bit_depth(), o.compression)
        frames = parse_frames(o.frames) if o.frames else None
        there = resolve_inputs(pout, frames, skip_missing=True)
        for _, path in there:
            role = self._read_by(path)
            if role is not None:
                raise ImageIOError(f"output {path} is an input of this render ({role}); clfx "
                                   f"never overwrites its inputs")
        if there and not (o.overwrite or o.skip_existing):
            more = f" (and {len(there) - 1} more)" if len(there) > 1 else ""
            raise OutputExistsError(f"output {there[0][1]} exists{more} (use "
                                    f"{option('--overwrite')} to replace it, or "
                                    f"{option('--skip-existing')} to keep it)")
