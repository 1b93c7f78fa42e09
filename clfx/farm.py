"""Render-farm job descriptions: the same chunks of frames any farm can run.

`openjd_template` writes an Open Job Description template (``jobtemplate-2023-09``, read by
AWS Deadline Cloud and any OpenJD scheduler; ``openjd check`` / ``openjd run`` test it
locally).  Its one step has a frame-range parameter space cut into chunks of ``chunk`` frames
(the ``TASK_CHUNKING`` extension's ``CHUNK[INT]`` parameter, or explicit chunk ranges for
schedulers without it), and each task runs::

    clfx render IN/NAME.#.exr OUT/NAME.#.exr --look LOOK --frames A-B --skip-existing

so a retried or resumed task re-renders only the frames whose output is missing, and writes
are atomic (a killed task leaves no partial frame).  Chunks are written as ``a-b`` or
``a-b:n`` (step n), the farm range syntax ``--frames`` reads.  The mapping to OpenCue,
Deadline 10 and Tractor is in ``docs/scaling.md``.
"""
from __future__ import annotations

import os

import yaml

from clfx.core.errors import ClfxError, SequenceError
from clfx.io.sequence import Pattern, compact, hash_notice, parse_frames
from clfx.pipeline.presets import apply_overrides, load_look

SPEC_VERSION = "jobtemplate-2023-09"
CANCEL_NOTIFY_S = 30
"""Seconds between SIGTERM (clfx removes its temp file and exits 143) and SIGKILL."""


def farm_range(frames) -> str:
    """Frames as an OpenJD / farm range expression: ``[1, 3, 5, 6, 7]`` -> ``"1-5:2,6-7"``
    (ascending; fileseq's ``x`` step written as ``:``)."""
    return compact(sorted(set(frames))).replace("x", ":")


def chunk_ranges(frames, chunk: int) -> list[str]:
    """Consecutive chunks of ``chunk`` frames (in ascending order), each as a range."""
    frames = sorted(set(frames))
    return [farm_range(frames[i:i + chunk]) for i in range(0, len(frames), chunk)]


def resolve_frames(input_path: str, frames: str | None) -> list[int]:
    """The frames to render: ``frames`` parsed, else every frame of ``input_path`` on disk."""
    if frames:
        return parse_frames(frames)
    pattern = Pattern.parse(input_path)
    found = pattern.existing_frames()
    if not found:
        hint = hash_notice(pattern)
        raise SequenceError(f"no frames of {input_path} found here (looked for files like "
                            f"{pattern.path(1)}); give --frames"
                            + (f"; {hint}" if hint else ""))
    return found


def task_args(input_path: str, output_path: str, look: str, frames: str, *,
              assignments=(), quality: str | None = None, render_args=()) -> list[str]:
    """The arguments of ``clfx`` that one farm task runs on its chunk ``frames``."""
    cmd = ["render", input_path, output_path, "--look", look, "--frames", frames,
           "--skip-existing"]
    for a in assignments:
        cmd += ["--set", a]
    if quality:
        cmd += ["--quality", quality]
    return cmd + list(render_args)


def openjd_template(input_path: str, output_path: str, *, look: str = "default",
                    assignments=(), frames: str | None = None, chunk: int = 10,
                    quality: str | None = None, render_args=(), name: str | None = None,
                    clfx: str = "clfx", task_chunking: bool = True,
                    path_params: bool = False) -> dict:
    """An Open Job Description job template rendering INPUT to OUTPUT in chunks.

    Parameters
    ----------
    input_path, output_path : str
        Frame patterns (``shot.#.exr``); made absolute, then split into a folder and a
        file pattern (job parameters ``InputDir``, ``InputName``, ``OutputDir``,
        ``OutputName``).
    look : str
        Look name or YAML file (a file becomes a PATH parameter).  Checked here with
        ``assignments`` (``--set`` values) so a bad look fails before submission.
    frames : str, optional
        Frame range; default every input frame on disk.
    chunk : int
        Frames per task (the ``ChunkSize`` job parameter's default).
    render_args : sequence of str
        More ``clfx render`` options for every task (``--compression dwaa``, ...).
    clfx : str
        The command farm workers run (the ``ClfxCommand`` job parameter's default).
    task_chunking : bool
        Use the ``TASK_CHUNKING`` extension (``CHUNK[INT]``; the scheduler may resize
        chunks); False lists the chunk ranges explicitly for schedulers without it.
    path_params : bool
        False (shared storage): the folders (and a look file) are STRING parameters whose
        defaults are the absolute paths given, so ``openjd run job.yaml`` renders as is.
        True: they are PATH parameters (``dataFlow`` IN/OUT), which farms map between
        operating systems and Deadline Cloud uses for job attachments; OpenJD wants PATH
        defaults relative to the template, so they have none: give them at submission
        (``-p InputDir=...``).

    Returns
    -------
    dict
        The template, ready for ``yaml.safe_dump``.

    Raises
    ------
    SequenceError
        INPUT or OUTPUT has no frame token, bad range, no frames.
    PresetError, ParamError
        The look or an assignment is invalid.
    """
    if chunk < 1:
        raise SequenceError(f"--chunk {chunk}: expected 1 or more frames per task")
    for path in (input_path, output_path):
        if not Pattern.parse(path).is_sequence:
            raise SequenceError(f"{path} has no frame token; a farm job renders a sequence "
                                f"(use e.g. shot.#.exr)")
    apply_overrides(load_look(look), list(assignments))
    frame_list = resolve_frames(input_path, frames)
    in_dir, in_name = os.path.split(os.path.abspath(input_path))
    out_dir, out_name = os.path.split(os.path.abspath(output_path))
    look_file = os.path.isfile(look)

    def folder(name, default, flow, kind, text):
        if not path_params:
            return _string_param(name, default, text)
        return {"name": name, "type": "PATH", "objectType": kind, "dataFlow": flow,
                "description": f"{text} (was {default})"}

    params = [
        folder("InputDir", in_dir, "IN", "DIRECTORY", "Folder of the input frames."),
        _string_param("InputName", in_name, "Input frame pattern in InputDir."),
        folder("OutputDir", out_dir, "OUT", "DIRECTORY", "Folder the frames are written to."),
        _string_param("OutputName", out_name, "Output frame pattern in OutputDir."),
        (folder("LookFile", os.path.abspath(look), "IN", "FILE", "The look (YAML file).")
         if look_file else _string_param("Look", look, "Look name (see `clfx looks`).")),
        _string_param("ClfxCommand", clfx, "The clfx executable on the workers."),
    ]
    if task_chunking:
        params += [
            _string_param("Frames", farm_range(frame_list), "Frames to render (a-b, a-b:n, lists)."),
            {"name": "ChunkSize", "type": "INT", "default": chunk, "minValue": 1,
             "description": "Frames per task."},
        ]
        frames_param = {"name": "Frames", "type": "CHUNK[INT]", "range": "{{Param.Frames}}",
                        "chunks": {"defaultTaskCount": "{{Param.ChunkSize}}",
                                   "rangeConstraint": "CONTIGUOUS"}}
    else:
        frames_param = {"name": "Frames", "type": "STRING",
                        "range": chunk_ranges(frame_list, chunk)}
    user = task_args("", "", "", "", assignments=assignments, quality=quality,
                     render_args=render_args)[len(task_args("", "", "", "")):]
    literal, user = _literal_args(user)
    params += literal
    args = task_args("{{Param.InputDir}}/{{Param.InputName}}",
                     "{{Param.OutputDir}}/{{Param.OutputName}}",
                     "{{Param.LookFile}}" if look_file else "{{Param.Look}}",
                     "{{Task.Param.Frames}}") + user
    template = {"specificationVersion": SPEC_VERSION}
    if task_chunking:
        template["extensions"] = ["TASK_CHUNKING"]
    template.update({
        "name": name or _plain(f"clfx {os.path.basename(look)} {in_name}")[:MAX_NAME],
        "description": f"clfx render {input_path} -> {output_path}, look {look}, "
                       f"{len(frame_list)} frame(s), {chunk} per task",
        "parameterDefinitions": params,
        "steps": [{
            "name": "Render",
            "parameterSpace": {"taskParameterDefinitions": [frames_param]},
            "script": {"actions": {"onRun": {
                "command": "{{Param.ClfxCommand}}",
                "args": args,
                "cancelation": {"mode": "NOTIFY_THEN_TERMINATE",
                                "notifyPeriodInSeconds": CANCEL_NOTIFY_S},
            }}},
        }],
    })
    check_template(template, path_params=path_params)
    return template


MAX_NAME = 128
"""OpenJD's longest job name."""


def _plain(text: str) -> str:
    """``text`` without braces: a default job name (a format string) built from file names."""
    return text.replace("{", "").replace("}", "")


def _literal_args(args: list[str]) -> tuple[list[dict], list[str]]:
    """Task arguments are OpenJD format strings, which have no escape for ``{{``: each user
    argument with a brace becomes a STRING job parameter (``Arg1``...; values are never
    expanded) that the argument names.  Returns (those parameters, the arguments)."""
    params, out = [], []
    for a in args:
        if "{" in a or "}" in a:
            pname = f"Arg{len(params) + 1}"
            params.append(_string_param(pname, a, "A clfx render argument, kept as written."))
            a = "{{Param.%s}}" % pname
        out.append(a)
    return params, out


def check_template(template: dict, *, path_params: bool = False) -> None:
    """Refuse a template OpenJD would refuse (`openjd check`, and a job made from its
    defaults), in one line naming what OpenJD says."""
    # lazy: openjd is optional (the test extra): only checking a template needs it
    from openjd.model import DecodeValidationError, create_job, decode_job_template

    try:
        decoded = decode_job_template(template=template,
                                      supported_extensions=template.get("extensions", []))
        if not path_params:       # PATH parameters have no defaults: given at submission
            create_job(job_template=decoded, job_parameter_values={})
    except (DecodeValidationError, ValueError) as exc:
        lines = [line.strip() for line in str(exc).splitlines()[1:] if line.strip()]
        what = "; ".join(f"{a} {b}" for a, b in zip(lines[::2], lines[1::2])) or \
            " ".join(str(exc).split())
        raise FarmError(f"the OpenJD template would be invalid: {what}") from None


class FarmError(ClfxError):
    """A job description a farm would refuse."""


def openjd_yaml(template: dict) -> str:
    return yaml.safe_dump(template, sort_keys=False, width=100)


def _string_param(name: str, default: str, text: str) -> dict:
    return {"name": name, "type": "STRING", "default": default, "minLength": 1,
            "description": text}
