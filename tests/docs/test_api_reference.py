#!/usr/bin/env python3
"""The C++ API reference (docs/Doxyfile) builds, and the checked headers are fully documented
(issue 23 part 5; CTest: docs.api_reference).

Runs Doxygen with docs/Doxyfile (every */include directory of the source tree as input, output
and warning log in --out), then sorts its warnings by header:
  - a warning in a header listed in tests/docs/api_checked_headers.txt fails the test (an
    undocumented public member, or documentation that does not fit the code);
  - a listed header that no longer exists fails the test (rename it in the list);
  - for every other header the warnings are printed as a to-do list, and headers that have become
    clean are named so that they can be added to the list.
Before that, a self-check runs Doxygen on a two-function header of its own, to prove that an
undocumented function is reported. Standard library only."""
import argparse
import collections
import pathlib
import re
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parents[2]


def run_doxygen(doxygen, source, inputs, out, extra=()):
    """Runs Doxygen on docs/Doxyfile with INPUT, OUTPUT_DIRECTORY and WARN_LOGFILE overridden;
    returns the warning lines (continuation lines joined)."""
    out.mkdir(parents=True, exist_ok=True)
    log = out / "warnings.txt"
    config = (ROOT / "docs" / "Doxyfile").read_text(encoding="utf-8")
    config += "\n" + "\n".join([
        "INPUT = " + " ".join(f'"{p}"' for p in inputs),
        f'OUTPUT_DIRECTORY = "{out}"',
        f'WARN_LOGFILE = "{log}"',
        f'STRIP_FROM_PATH = "{source}"',
        "USE_MDFILE_AS_MAINPAGE = " + (f'"{inputs[0]}"' if str(inputs[0]).endswith(".md") else ""),
        *extra]) + "\n"
    done = subprocess.run([doxygen, "-"], input=config, text=True, cwd=source, capture_output=True)
    if done.returncode != 0:
        sys.exit(f"doxygen failed (exit status {done.returncode}):\n{done.stdout}\n{done.stderr}")
    warnings = []
    for line in log.read_text(encoding="utf-8", errors="replace").splitlines():
        if line.startswith((" ", "\t")) and warnings:
            warnings[-1] += " " + line.strip()
        elif line.strip():
            warnings.append(line.strip())
    return warnings


def by_header(warnings, source):
    """{relative header path: [warning text]}, and the warnings that name no file."""
    grouped, loose = collections.defaultdict(list), []
    pattern = re.compile(r"^(/[^:]+|[^:/][^:]*):(\d+): (?:warning: )?(.*)$")
    for w in warnings:
        m = pattern.match(w)
        if not m:
            loose.append(w)
            continue
        path = pathlib.Path(m.group(1))
        if not path.is_absolute():
            path = source / path
        try:
            rel = path.resolve().relative_to(source.resolve()).as_posix()
        except ValueError:
            rel = path.as_posix()
        grouped[rel].append(f"line {m.group(2)}: {m.group(3)}")
    return grouped, loose


def self_check(doxygen, scratch):
    """Doxygen and the parser report an undocumented function and only that one."""
    include = scratch / "include"
    include.mkdir(parents=True)
    (include / "probe.hpp").write_text(
        "#pragma once\n/// @file\n/// A probe header.\nnamespace probe {\n"
        "/// Twice x.\nint twice(int x);\n"
        "int undocumented(int x);\n}\n", encoding="utf-8")
    grouped, loose = by_header(run_doxygen(doxygen, scratch, [include], scratch / "out"), scratch)
    found = grouped.get("include/probe.hpp", [])
    if len(found) != 1 or "undocumented" not in found[0] or loose:
        sys.exit(f"self-check failed: expected one warning about 'undocumented' in probe.hpp, got "
                 f"{dict(grouped)} {loose}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--doxygen", default="doxygen")
    ap.add_argument("--out", required=True, help="output directory (HTML and the warning log)")
    ap.add_argument("--checked", default=str(ROOT / "tests" / "docs" / "api_checked_headers.txt"))
    args = ap.parse_args(argv)
    out = pathlib.Path(args.out).resolve()

    with tempfile.TemporaryDirectory() as scratch:
        self_check(args.doxygen, pathlib.Path(scratch))

    inputs = [ROOT / "docs" / "api_mainpage.md"] + sorted(p for p in ROOT.glob("*/include") if p.is_dir())
    warnings = run_doxygen(args.doxygen, ROOT, inputs, out)
    grouped, loose = by_header(warnings, ROOT)
    if not (out / "html" / "index.html").exists():
        sys.exit(f"{out}/html/index.html was not written")

    checked = [l.strip() for l in pathlib.Path(args.checked).read_text(encoding="utf-8").splitlines()
               if l.strip() and not l.startswith("#")]
    headers = sorted(p.relative_to(ROOT).as_posix() for d in inputs[1:] for p in d.rglob("*.hpp")
                     if "detail" not in p.relative_to(d).parts)
    failures = [f"{h}: listed in {args.checked} but not in the tree (moved? rename it there)"
                for h in checked if not (ROOT / h).exists()]
    for h in checked:
        failures += [f"{h}: {w}" for w in grouped.get(h, [])]
    failures += [f"(no file): {w}" for w in loose]

    todo = {h: grouped[h] for h in headers if h not in checked and grouped.get(h)}
    clean = [h for h in headers if h not in checked and not grouped.get(h)]
    print(f"API reference: {out / 'html' / 'index.html'}; {len(headers)} public headers, "
          f"{len(checked)} checked, {len(warnings)} Doxygen warnings in all")
    if todo:
        print(f"\nNot yet checked ({len(todo)} headers, {sum(map(len, todo.values()))} warnings):")
        for h, ws in todo.items():
            undocumented = sum("is not documented" in w for w in ws)
            print(f"  {h}: {undocumented} undocumented, {len(ws) - undocumented} other")
            for w in ws[:3]:
                print(f"      {w}")
            if len(ws) > 3:
                print(f"      ... {len(ws) - 3} more (full list: {out / 'warnings.txt'})")
    if clean:
        print("\nClean but not listed (add them to the checked list):\n  " + "\n  ".join(clean))
    if failures:
        print("\nFAILED: warnings in checked headers:\n  " + "\n  ".join(failures))
        return 1
    print("\nchecked headers: no warnings")
    return 0


if __name__ == "__main__":
    sys.exit(main())
