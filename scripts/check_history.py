#!/usr/bin/env python3
"""check_history.py — user-facing text speaks about the product, not about how it was made.

Usage: check_history.py ROOT LUMOSAIC
       check_history.py --self-test   (the patterns against examples of both kinds)

Searches README.md, every Markdown page under docs/, the output of `lumosaic --help`, of every
command's `--help` and of `info --list`, and the comments of every C/OpenCL source for words of
development history: numbered work periods ("Session 9", "sessions 6-9", "this session"),
issue references ("issue 13", "(issue", "#12"), "previously", "the previous demo", "git show",
commit hashes in parentheses; and, in pages and help texts, references to files outside the
repository ("system.md §9", "models.md", "the supplement"). History belongs in CHANGELOG.md (not searched). Prints each hit
as FILE:LINE: TEXT and exits 1 if there is any, 0 otherwise.
"""
import os
import re
import subprocess
import sys

PATTERNS = [
    (r"\b[Ss]essions? [0-9]", "numbered work session"),
    (r"(?<![/_\w])[Ss]essions?\b(?!\.[ch]\b)(?!\()", "work session"),
    (r"\b[Ii]ssues? [0-9]+", "issue number"),
    (r"\(issue\b", "issue reference"),
    (r"\bthe issue's\b", "issue reference"),
    (r"(?<![#\w&(/.])#[0-9]+\b(?!-)", "issue number (#N)"),
    (r"\b[Pp]reviously\b", "earlier state"),
    (r"\b[Pp]revious (demo|session|alignment|binary|version of)\b", "earlier state"),
    (r"\bgit (show|history)\b|\bin git history\b", "repository history"),
    (r"\((?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,12}\)", "commit hash"),
]
REGEX = [(re.compile(p), why) for p, why in PATTERNS]
# Pages and help texts also must not send the user to files outside the repository.
OUTSIDE = [
    (r"(?<![/\w])system\.md ?§", "a section of a file outside the repository (use docs/system.md#...)"),
    (r"(?<![/\w])(models|design|style)\.md\b", "a file outside the repository"),
    (r"\b[Tt]he supplement\b", "the paper's supplement (not in the repository)"),
    (r"shared/(docs|reference)\b", "a file outside the repository"),
]
OUTSIDE = [(re.compile(p), why) for p, why in OUTSIDE]


def c_comments(text):
    """(line, comment text) of every /* */ and // comment, skipping string and char literals."""
    out, i, n, line = [], 0, len(text), 1
    while i < n:
        c = text[i]
        if c == "\n":
            line += 1
            i += 1
        elif c in "\"'":
            q, i = c, i + 1
            while i < n and text[i] != q and text[i] != "\n":
                i += 2 if text[i] == "\\" else 1
            i += 1
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j
            for k, part in enumerate(text[i + 2:j].split("\n")):
                out.append((line + k, part))
            line += text.count("\n", i, j)
            i = j + 2
        elif text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append((line, text[i + 2:j]))
            i = j
        else:
            i += 1
    return out


def scan(name, lines, hits, extra=()):
    for no, text in lines:
        for rx, why in list(REGEX) + list(extra):
            m = rx.search(text)
            if m:
                hits.append(f"{name}:{no}: {why}: {text.strip()[:160]}")
                break


SHOULD_HIT = ["Session 9", "sessions 6-9", "until session 6", "as the session ended",
              "(issue 13, item 3)", "issue 18", "see #12", "previously 30 dB", "the previous demo model",
              "git show cc3afa1:x", "a binary (a33fc87) in which",
              "(system.md §10)", "as in models.md.", "the supplement, \"Calibration\"",
              "../shared/docs/system.md"]
SHOULD_PASS = ["train/session.c", "lm_train_session(&cfg)", "session(cfg, opts)", "a##i##0",
               "#include <x.h>", "[link](system.md#4-forward-model)", "## 4. Forward model",
               "a known issue with the driver", "0x9e3779b9", "seed 12345678", "previous frame",
               "[the system](docs/system.md#4-forward-model)", "docs/system.md", "supplementary data"]


def self_test():
    """The patterns find every kind of history and leave legitimate words alone."""
    rxs = [rx for rx, _ in REGEX + OUTSIDE]
    bad = [t for t in SHOULD_HIT if not any(rx.search(t) for rx in rxs)]
    bad += [t for t in SHOULD_PASS if any(rx.search(t) for rx in rxs)]
    for t in bad:
        print(f"check_history self-test: wrong verdict on {t!r}")
    return 1 if bad else 0


def main():
    if sys.argv[1:] == ["--self-test"]:
        return self_test()
    if len(sys.argv) != 3:
        sys.exit("usage: check_history.py ROOT LUMOSAIC")
    root, lm = sys.argv[1], sys.argv[2]
    hits = []
    pages = [os.path.join(root, "README.md")]
    for d, _, files in os.walk(os.path.join(root, "docs")):
        pages += [os.path.join(d, f) for f in sorted(files) if f.endswith(".md")]
    for p in pages:
        with open(p, encoding="utf-8") as f:
            scan(os.path.relpath(p, root), enumerate(f.read().split("\n"), 1), hits, OUTSIDE)
    skip = {"build", ".git"}
    for d, dirs, files in os.walk(root):
        dirs[:] = [x for x in dirs if x not in skip and not x.startswith("build")]
        for f in sorted(files):
            if f.endswith((".c", ".h", ".cl")):
                p = os.path.join(d, f)
                with open(p, encoding="utf-8", errors="replace") as fh:
                    scan(os.path.relpath(p, root), c_comments(fh.read()), hits)
    top = subprocess.run([lm, "--help"], capture_output=True, text=True).stdout
    cmds = re.findall(r"^  (\S+) ", top, re.M)
    runs = [["--help"]] + [[c, "--help"] for c in cmds if c != "help"] + [["info", "--list"]]
    for args in runs:
        r = subprocess.run([lm] + args, capture_output=True, text=True)
        text = r.stdout + r.stderr
        if r.returncode != 0 or not text.strip():
            hits.append(f"lumosaic {' '.join(args)}: exit {r.returncode}, no help text")
        scan("lumosaic " + " ".join(args), enumerate(text.split("\n"), 1), hits, OUTSIDE)
    for h in hits:
        print(h)
    if hits:
        print(f"check_history: {len(hits)} line(s) of development history or outside references in "
              "user-facing text; say it for the user (history goes to CHANGELOG.md; link into docs/)")
        return 1
    print(f"check_history: {len(pages)} pages, {len(runs)} help texts and the C comments are clean")
    return 0


if __name__ == "__main__":
    sys.exit(main())
