#!/usr/bin/env python3
"""check_layers.py — the include graph between top-level folders, checked against the folder
table of design.md ("may use" column): every `#include "..."` of every .c/.h/.cpp file in a
top-level folder must point into the same folder or into one the table lets it use.

What it is: a scan of the quoted includes (system headers in <...> are libraries, not arrows;
.cl kernels are not C includes); an include resolves next to the including file first, then
from the repository root. It prints every forbidden arrow as `file:line: #include "x": folder/
may use ...` and exits 1; a C file in a top-level folder the table does not know also fails.
What it is not: a check of what a file calls (a symbol reached through an allowed header is
not seen) or of transitive includes. Run by CTest (test check_layers) and by hand:
    python3 scripts/check_layers.py [REPO_ROOT]
"""
import os
import re
import subprocess
import sys

ALL = None  # may use every folder

# design.md, "Folders": folder -> the folders (or single headers) it may include.
# Arrows only point down the table; infer/ never uses train/; nothing above tensor/ names
# OpenCL (kernels-opencl/) except the program (cli/); models/ may use data/ for the mosaic
# description only.
RULES = {
    "tensor": set(),
    "autograd": {"tensor"},
    "kernels-opencl": {"tensor"},
    "data": {"tensor", "include"},
    "models": {"tensor", "autograd", "data/mosaic.h"},
    "train": {"tensor", "autograd", "data", "models"},
    "infer": {"tensor", "data", "models", "include"},
    "include": set(),  # the public C API's header: standalone, implemented by data/, infer/
    "examples": {"include"},  # programs on the public C API only
    "study": {"tensor", "autograd", "data", "models", "train", "infer"},  # train, infer and below
    "cli": ALL,
    "bench": ALL,
    "tests": ALL,
}
# Top-level folders without C sources of the library (nothing to check in them).
NOT_CODE = {"cmake", "docs", "scripts"}
SOURCE_EXT = (".c", ".h", ".cpp")
INCLUDE = re.compile(r'^\s*#\s*include\s*"([^"]+)"')


def source_files(root):
    """Repository files (tracked and untracked, not ignored) with a C/C++ extension; without
    git, every file under the folders of the table."""
    try:
        out = subprocess.run(["git", "-C", root, "ls-files", "-co", "--exclude-standard"],
                             check=True, capture_output=True, text=True).stdout
        files = [f for f in out.splitlines() if f.endswith(SOURCE_EXT)]
        return sorted(f for f in files if os.path.exists(os.path.join(root, f)))
    except (OSError, subprocess.CalledProcessError):
        files = []
        for top in RULES:
            for d, _, names in os.walk(os.path.join(root, top)):
                files += [os.path.relpath(os.path.join(d, n), root) for n in names
                          if n.endswith(SOURCE_EXT)]
        return sorted(files)


def resolve(root, src, inc):
    """Repository path of include `inc` written in file `src` (both relative to root), or None
    for a header that is not the project's."""
    here = os.path.normpath(os.path.join(os.path.dirname(src), inc))
    if not here.startswith("..") and os.path.exists(os.path.join(root, here)):
        return here
    top = os.path.normpath(inc).split(os.sep)[0]
    return os.path.normpath(inc) if top in RULES else None


def allowed(folder, target):
    rule = RULES[folder]
    tfolder = target.split(os.sep)[0]
    return rule is ALL or tfolder == folder or tfolder in rule or target in rule


def describe(folder):
    rule = RULES[folder]
    return "everything" if rule is ALL else (", ".join(sorted(rule)) or "no other folder")


def main():
    root = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else
                           os.path.join(os.path.dirname(__file__), ".."))
    bad, nfiles, nincs = [], 0, 0
    for f in source_files(root):
        parts = f.split("/")
        if len(parts) < 2 or parts[0] in NOT_CODE:
            continue
        folder = parts[0]
        if folder not in RULES:
            bad.append(f"{f}: folder {folder}/ is not in design.md's table")
            continue
        nfiles += 1
        with open(os.path.join(root, f), encoding="utf-8", errors="replace") as fh:
            for ln, line in enumerate(fh, 1):
                m = INCLUDE.match(line)
                target = resolve(root, f, m.group(1)) if m else None
                if target is None:
                    continue
                nincs += 1
                if not allowed(folder, target):
                    bad.append(f'{f}:{ln}: #include "{m.group(1)}": {folder}/ may use '
                               f"{describe(folder)} (design.md)")
    for b in bad:
        print(b)
    if bad:
        print(f"check_layers: {len(bad)} include(s) against design.md's table "
              f"({nfiles} files, {nincs} project includes)")
        return 1
    print(f"check_layers: {nfiles} files, {nincs} project includes, every arrow allowed by "
          f"design.md's table")
    return 0


if __name__ == "__main__":
    sys.exit(main())
