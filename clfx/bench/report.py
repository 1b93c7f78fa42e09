"""The bench's results as markdown: the summary, each effect's levels, baselines and peers,
the cases scored against a path tracer, looks, the sequence and the scene analysis."""
from __future__ import annotations

from clfx.core.plugin import QUALITY_LEVELS


def losing_levels(effect: dict) -> list[str]:
    """``level: loses to naive/input`` for every flagged level of an effect's results."""
    out = []
    for r in effect.get("rows", []):
        lost = [b for b, k in (("naive", "beats_naive"), ("input", "beats_input"),
                               ("peer", "beats_peer")) if r.get(k) is False]
        if lost:
            out.append(f"{r['quality']} loses to the {' and the '.join(lost)}")
    return out


def _yes_no(value) -> str:
    return "-" if value is None else ("yes" if value else "NO")


def summary_markdown(results: dict) -> str:
    """One row per effect (and case variant): median ms and relative RMSE (vs the reference
    level or the ground truth) at each quality level, the log-PSNR of the naive method and of
    the unchanged input, and the levels that lose to either."""
    lines = ["| effect | " + " | ".join(QUALITY_LEVELS) + " | naive / input PSNR log (dB) | "
             "every level beats naive / input | error measured against |",
             "|---|" + "---|" * len(QUALITY_LEVELS) + "---|---|---|"]
    for e in results.get("effects", []):
        rows = {r["quality"]: r for r in e["rows"]}
        if not rows:
            lines.append(f"| {e['effect']} | {e['note']} |" + " |" * (len(QUALITY_LEVELS) + 2))
            continue
        cells = []
        for q in QUALITY_LEVELS:
            r = rows[q]
            err = r["rel_rmse"]
            baseline = q == "reference" and e["reference"] == "reference level"
            cells.append(f"{r['ms']:.0f} ms, " + ("baseline" if baseline else
                                                   "0" if err == 0 else f"{err:.1e}"))
        base = {b["baseline"]: b for b in e.get("baselines", [])}
        psnr = " / ".join(_psnr_cell(base.get(k)) for k in ("naive", "input"))
        flags = " / ".join(_all_yes(e["rows"], k) for k in ("beats_naive", "beats_input"))
        lost = losing_levels(e)
        lines.append(f"| {e['effect']} | " + " | ".join(cells) + f" | {psnr} | {flags}"
                     + (f" ({'; '.join(lost)})" if lost else "") + f" | {e['reference']} |")
    return "\n".join(lines) + "\n"


def _psnr_cell(row: dict | None) -> str:
    if row is None:
        return "-"
    if "error" in row:
        return "failed"
    return f"{row['psnr_log']:.1f}"


def _all_yes(rows: list[dict], key: str) -> str:
    values = [r.get(key) for r in rows]
    if all(v is None for v in values):
        return "-"
    return "NO" if any(v is False for v in values) else "yes"


def markdown(results: dict) -> str:
    lines = [f"clfx bench at {results['size'][0]}x{results['size'][1]}, {results['repeat']} warm "
             f"runs, device: {results['device']}", ""]
    if results.get("effects"):
        lines += ["Time per frame and relative RMSE of each quality level:", "",
                  summary_markdown(results), "Details (each effect's levels, then its naive "
                  "method and the unchanged input, scored against the same reference):", ""]
    if results.get("effects"):
        lines += ["| effect | level | ms (min-max) | speed-up vs ref | RMSE | max err | rel. RMSE | "
                  "PSNR log (dB) | edge RMSE | beats naive / beats input | reference |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for e in results["effects"]:
            for r in e["rows"]:
                sp = r.get("speedup_vs_reference")
                flags = f"{_yes_no(r.get('beats_naive'))} / {_yes_no(r.get('beats_input'))}"
                lines.append(
                    f"| {r['effect']} | {r['quality']} | {r['ms']:.1f} ({r['ms_min']:.1f}-{r['ms_max']:.1f}) | "
                    f"{sp:.2f}x | {r['rmse']:.3g} | {r['max_err']:.3g} | {r['rel_rmse']:.3g} | "
                    f"{r['psnr_log']:.1f} | {r.get('edge_rmse', float('nan')):.3g} | {flags} | "
                    f"{r['reference']} |"
                    if sp else f"| {r['effect']} | {r['quality']} | identity | | | | | | | | |")
            for b in e.get("baselines", []):
                what = f"{b['baseline']}: {b['label']}"
                if "error" in b:
                    lines.append(f"| {b['effect']} | {what} | failed: {b['error']} | | | | | | | | |")
                    continue
                ms = f"{b['ms']:.1f} ({b['ms_min']:.1f}-{b['ms_max']:.1f})" if "ms" in b else "-"
                lines.append(
                    f"| {b['effect']} | {what} | {ms} | | {b['rmse']:.3g} | {b['max_err']:.3g} | "
                    f"{b['rel_rmse']:.3g} | {b['psnr_log']:.1f} | {b.get('edge_rmse', float('nan')):.3g} "
                    f"| | {e['reference']} |")
            notes = [f"- {e['effect']}: {e['metric']}" for e in results["effects"] if e.get("metric")]
        if notes:
            lines += ["", "Scored by the case's own metric (RMSE, max err, rel. RMSE and PSNR log "
                          "above are its quantities):", *notes]
        peers = [p for e in results["effects"] for p in e["peers"]]
        if peers:
            lines += ["", "Peers, each timed alternately with the clfx level it is compared with "
                          "(clfx ms: that level's median in those runs; clfx / peer time: the "
                          "median of the runs' ratios):",
                      "", "| effect | peer | peer ms | clfx level | clfx ms | clfx / peer time | "
                          "peer rel. RMSE | clfx rel. RMSE | peer / clfx PSNR log (dB) | peer max err |",
                      "|---|---|---|---|---|---|---|---|---|---|"]
            for p in peers:
                if "error" in p:
                    lines.append(f"| {p['effect']} | {p['peer']} | failed: {p['error']} | | | | | | | |")
                else:
                    lines.append(f"| {p['effect']} | {p['peer']} | {p['ms']:.1f} | {p['clfx_level']} | "
                                 f"{p['clfx_ms']:.1f} | {p['clfx_time_ratio']:.2f} | {p['rel_rmse']:.3g} | "
                                 f"{p['clfx_rel_rmse']:.3g} | {p['psnr_log']:.1f} / "
                                 f"{p.get('clfx_psnr_log', float('nan')):.1f} | {p['max_err']:.3g} |")
    lines += truth_markdown(results)
    if results.get("looks"):
        lines += ["", "| look | ms/frame (min-max) | per effect (ms) |", "|---|---|---|"]
        for lk in results["looks"]:
            per = ", ".join(f"{k} {v:.0f}" for k, v in lk["effects"].items())
            lines.append(f"| {lk['look']} | {lk['ms']:.0f} ({lk['ms_min']:.0f}-{lk['ms_max']:.0f}) | {per} |")
    if results.get("sequence"):
        lines += ["", *sequence_markdown(results["sequence"])]
    if results.get("analysis"):
        a = results["analysis"]
        lines += ["", f"What a scene calls for (look {a['look']}; EXR read {a['read_ms']:.0f} ms + "
                      f"write {a['write_ms']:.0f} ms = {a['io_ms']:.0f} ms):", "",
                  "| frame | device ms | (device + I/O) / I/O | skipped |", "|---|---|---|---|"]
        for k, r in a["frames"].items():
            skipped = "; ".join(f"{e}: {why}" for e, why in r["skipped"].items()) or "-"
            lines.append(f"| {k} | {r['ms']:.0f} | {r['vs_io']:.2f} | {skipped} |")
    return "\n".join(lines) + "\n"


def truth_markdown(results: dict) -> list[str]:
    """The cases whose truth is rendered with a seed (a path tracer's, or the layered scenes'
    jittered renders), one row each: log-PSNR (dB) of the input, the naive method, every peer
    image (Blender's Vector Blur), each level, and the truth's own noise floor (a second
    render with another seed, against the truth)."""
    cases = [e for e in results.get("effects", []) if e.get("truth_floor") is not None
             or str(e.get("scene", "")).startswith("cycles:")
             or any(b["baseline"] == "peer" for b in e.get("baselines", []))]
    if not cases:
        return []
    lines = ["", "Against a truth rendered with a seed (a path tracer's or the layered scenes' "
                 "jittered render; log-PSNR dB; noise floor: the same render with another seed, "
                 "against the truth):", "",
             "| case | input | naive | peer | " + " | ".join(QUALITY_LEVELS)
             + " | noise floor | final beats input / naive / peer |",
             "|---|---|---|---|" + "---|" * len(QUALITY_LEVELS) + "---|---|"]
    for e in cases:
        base = {}
        for b in e.get("baselines", []):
            base.setdefault(b["baseline"], b)
        rows = {r["quality"]: r for r in e["rows"]}
        levels = " | ".join(f"{rows[q]['psnr_log']:.1f}" if q in rows and "psnr_log" in rows[q]
                            else "-" for q in QUALITY_LEVELS)
        floor = e.get("truth_floor")
        fin = rows.get("final", {})
        flags = " / ".join(_yes_no(fin.get(k)) for k in ("beats_input", "beats_naive", "beats_peer"))
        lines.append(f"| {e['effect']} | {_psnr_cell(base.get('input'))} | "
                     f"{_psnr_cell(base.get('naive'))} | {_psnr_cell(base.get('peer'))} | {levels} | "
                     f"{'-' if floor is None else f'{floor:.1f}'} | {flags} |")
    return lines


def sequence_markdown(s: dict) -> list[str]:
    """The sequence tables: the stream end to end, then where a frame's time and CPU went,
    part by part (read, upload, each step, download, write), alone and in the stream."""
    def ms(v):
        return "-" if v is None else f"{v:.0f}"

    load = f", load average {s['load_avg']:.1f} on {s['cores']} cores" if s.get("load_avg") is not None else ""
    mode = f", {s['stream']} stream" if s.get("stream") else ""
    io = (f"; reading and writing a frame alone take {s['io_ms']:.0f} ms, the stream "
          f"{s['stream_vs_io']:.2f}x that") if s.get("stream_vs_io") else ""
    io_cpu = (f" (CPU: {s['stream_cpu_vs_io']:.2f}x the {s['io_cpu_ms']:.0f} ms reading and "
              f"writing take alone"
              + (f", which take {s['io_cpu_in_stream_ms']:.0f} ms in the stream"
                 if s.get("io_cpu_in_stream_ms") is not None else "") + ")") \
        if s.get("stream_cpu_vs_io") else ""
    lines = [f"Sequence (look {s['look']}, {s['frames']} frames, EXR read and write included"
             f"{mode}{load}): {s['ms_per_frame']:.0f} ms/frame ({s['fps']} fps) end to end; the same "
             f"parts one after another take {s['parts_ms']:.0f} ms, so the stream takes "
             f"{s['stream_vs_parts']:.2f}x its parts' sum{io}.  CPU time: "
             f"{s['cpu_ms_per_frame']:.0f} ms per frame in the stream, {s['parts_cpu_ms']:.0f} ms "
             f"for the parts alone{io_cpu}.", "",
             "Per frame (medians): wall ms alone and in the stream; of a step's stream ms, "
             "the host's (planning, enqueueing, waiting on reads back); CPU ms of the whole "
             "process (a CPU device's threads included).  Read includes decoding, write "
             "encoding; alone, each reads the stream's own frames or writes its output with "
             "the stream's compression.  In the stream a frame's write and the next read "
             "run side by side on the same codec threads, so their CPU is one figure, "
             "\"read + write\": the stream's CPU less its renders' (the loop's own included).",
             "", "| part | alone ms | in stream ms | in stream / alone | host ms | "
             "CPU ms alone | CPU ms in stream |", "|---|---|---|---|---|---|---|"]
    for r in s["rows"]:
        ratio = "-" if r["ratio"] is None else f"{r['ratio']:.2f}x"
        lines.append(f"| {r['part']} | {ms(r['alone_ms'])} | {ms(r['stream_ms'])} | {ratio} | "
                     f"{ms(r.get('host_ms'))} | {ms(r.get('alone_cpu_ms'))} | "
                     f"{ms(r.get('stream_cpu_ms'))} |")
    return lines
