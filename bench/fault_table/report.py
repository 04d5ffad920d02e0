"""The fault table's report: the text table, the README's markdown table, merging a partial re-run."""
from __future__ import annotations

import argparse
import os
import platform
import sys
from typing import Any, Dict, List, Tuple

from fault_table.harness import HOVER_SPEED_MS, HOVER_TOLERANCE_M, REPO, SAMPLE_HZ, Row
from fault_table.rows import rows


# --- output --------------------------------------------------------------------------------------
def table(results: List[Tuple[Row, Dict[str, Any]]]) -> List[str]:
    lines = []
    for row, r in results:
        if "error" in r:
            lines += ["%s (%s): bench error: %s" % (row.title, row.path, r["error"]), ""]
            continue
        lines.append("%s (%s path)" % (row.title, row.path))
        lines.append("  does:     %s" % r["does"])
        lines.append("  safe:     %s" % (r["safe"] or "not within the %.0f s observed" % row.observe_s))
        for i, where in enumerate(r["reported"] or ["nowhere"]):
            lines.append("  %s %s" % ("reported:" if i == 0 else "         ", where))
        lines.append("  lost:     %s" % ("; ".join(r["lost"]) or "nothing counted"))
        lines.append("  (bench: %.1f s to a hover before the fault%s)" % (
            r["setup_s"], "" if r["setup_s"] else ": the graph of the row before"))
        lines.append("")
    return lines


def markdown(results: List[Tuple[Row, Dict[str, Any]]]) -> List[str]:
    """The README's short table: one line per row."""
    out = ["| fault | path | what the stack does | safe state after | reported | lost |", "|---|---|---|---|---|---|"]
    for row, r in results:
        if "error" in r:
            out.append("| %s | %s | bench error: %s | | | |" % (row.title, row.path, r["error"]))
            continue
        where = sorted({w.split(" +")[0].replace("log WARN", "log").replace("log ERROR", "log")
                        .replace("log FATAL", "log") for w in r["reported"] if not w.startswith("controller")})
        if any(w.startswith("controller") for w in r["reported"]):
            where.append("controller state")
        safe = "—" if r.get("safe_s") is None else "%.2f s (%s)" % (
            r["safe_s"], "hover" if r["safe_kind"] == "hover" else "floor, motors off")
        out.append("| %s | %s | %s | %s | %s | %s |" % (row.title, row.path, r["does"], safe,
                                                        ", ".join(where) or "nowhere",
                                                        "; ".join(r["lost"]) or "—"))
    return out


# rows that usually leave the vehicle hovering first, so the graph is reused; the table keeps rows()'s order
RUN_FIRST = ("loss30", "loss80", "ackloss", "latency", "freeze02", "freeze2", "battery_warn", "unplug1")

README_TABLE = "README table:"


def previous_table(path: str) -> Tuple[List[str], Dict[str, Tuple[List[str], str]]]:
    """An earlier table file's head lines and its rows by key: (detail lines, README line); empty if none.

    Rows are found by their title and path, as :func:`table` and :func:`markdown` write them."""
    try:
        with open(path) as f:
            text = f.read()
    except OSError:
        return [], {}
    detail, _, short = text.partition("\n%s\n" % README_TABLE)
    blocks = detail.split("\n\n")
    head = blocks[0].split("\n") if blocks else []
    found: Dict[str, Tuple[List[str], str]] = {}
    for r in rows():
        starts = ("%s (%s path)" % (r.title, r.path), "%s (%s): bench error" % (r.title, r.path))
        block = next((b for b in blocks[1:] if b.strip("\n").split("\n")[0].startswith(starts)), None)
        line = next((x for x in short.split("\n") if x.startswith("| %s | %s |" % (r.title, r.path))), None)
        if block is not None and line is not None:
            found[r.key] = (block.strip("\n").split("\n") + [""], line)
    return head, found


def write(args: argparse.Namespace, results: List[Tuple[Row, Dict[str, Any]]], commit: str, took: float,
          partial: bool) -> None:
    """The table of ``results``; with ``--rows``, merged by row key into the table already in ``--out``
    (the rows not run keep their earlier lines, the head says which rows were measured again)."""
    results = sorted(results, key=lambda rr: [r.key for r in rows()].index(rr[0].key))
    if args.rows and args.out != "-":
        previous_head, previous = previous_table(args.out)
        if previous:
            write_merged(args, results, commit, took, partial, previous_head, previous)
            return
    head = ["fault table: one Crazyflie hovering at (0, 0, 0.5) in the full ROS stack (crazyflie_sim_node with "
            "Vicon-style mocap at 100 Hz, crazyflie_server over the fake Crazyradio; path chapter: the chapter's "
            "controller node; path onboard: the high-level commander with the mocap as external_position; "
            "path onboard+keep-alive: the same with the server's emergency-stop watchdog keep-alive on)",
            "safe = on the floor with the motors off, or within %.2f m of the goal and slower than %.1f m/s until "
            "the row ends; times from the fault; truth sampled at %.0f Hz" % (HOVER_TOLERANCE_M, HOVER_SPEED_MS,
                                                                             SAMPLE_HZ),
            "command: flock /tmp/ros.lock bench/bench_faults.py --readme   (%.0f s for %d rows%s)" % (
                took, len(results), ", run still going" if partial else ""),
            "stack at: %s" % commit,
            "machine: %s, %s, Python %s, %d CPUs, load average %s" % (
                platform.machine(), platform.platform(terse=True), platform.python_version(), os.cpu_count() or 0,
                " ".join("%.2f" % x for x in os.getloadavg())),
            ""]
    text = "\n".join(head + table(results) + ["", README_TABLE, ""] + markdown(results)) + "\n"
    if args.out == "-":
        if not partial:
            print("\n".join(markdown(results)))
        return
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        f.write(text)
    if args.readme:
        update_readme(markdown(results))
    if not partial:
        print("written to %s (%.0f s)" % (args.out, took))


def write_merged(args: argparse.Namespace, results: List[Tuple[Row, Dict[str, Any]]], commit: str, took: float,
                 partial: bool, previous_head: List[str], previous: Dict[str, Tuple[List[str], str]]) -> None:
    new = {row.key: (row, r) for row, r in results}
    detail, short = [], markdown([])
    for row in rows():
        if row.key in new:
            detail += table([new[row.key]])
            short += markdown([new[row.key]])[2:]
        elif row.key in previous:
            detail += previous[row.key][0]
            short.append(previous[row.key][1])
    tag = "re-measured (--rows %s):" % args.rows
    head = [line for line in previous_head if line and not line.startswith(tag)]
    head += ["%s stack at %s, %.0f s for %d rows%s, load average %s" % (
        tag, commit, took, len(results), ", run still going" if partial else "",
        " ".join("%.2f" % x for x in os.getloadavg())), ""]
    with open(args.out, "w") as f:
        f.write("\n".join(head + detail + ["", README_TABLE, ""] + short) + "\n")
    if args.readme:
        update_readme(short)
    if not partial:
        print("merged into %s (%.0f s)" % (args.out, took))


README_MARKERS = ("<!-- fault table: bench/bench_faults.py --readme writes below -->", "<!-- fault table end -->")


def update_readme(lines: List[str]) -> None:
    path = os.path.join(REPO, "README.md")
    with open(path) as f:
        text = f.read()
    start, end = text.find(README_MARKERS[0]), text.find(README_MARKERS[1])
    if start < 0 or end < start:
        print("bench_faults: README.md has no fault-table markers; table not copied", file=sys.stderr)
        return
    text = text[:start + len(README_MARKERS[0])] + "\n" + "\n".join(lines) + "\n" + text[end:]
    with open(path, "w") as f:
        f.write(text)
    print("README.md fault table updated")
