#!/usr/bin/env python3
"""check_links.py ROOT — every relative link of README.md and docs/**/*.md leads somewhere.

A link [text](path) or [text](path#anchor) must name a file or folder of the repository, and an
anchor in a Markdown page must be one of that page's headings (GitHub's anchors: lower case,
punctuation dropped, spaces to hyphens). Web links (http, https, mailto) are not followed.
Prints each broken link as PAGE:LINE: LINK and exits 1 if there is any.
"""
import os
import re
import sys

LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)|!\[[^\]]*\]\(([^)\s]+)\)")


def slug(heading):
    s = heading.strip().lower().replace("`", "")
    s = re.sub(r"[^\w\- ]", "", s)
    return s.replace(" ", "-")


def anchors(path, cache={}):
    if path not in cache:
        out, fence = set(), False
        for line in open(path, encoding="utf-8"):
            if line.startswith("```"):
                fence = not fence
            elif not fence and line.startswith("#"):
                out.add(slug(line.lstrip("#")))
        cache[path] = out
    return cache[path]


def main():
    root = sys.argv[1]
    pages = [os.path.join(root, "README.md")]
    for d, _, files in os.walk(os.path.join(root, "docs")):
        pages += [os.path.join(d, f) for f in sorted(files) if f.endswith(".md")]
    bad = 0
    for page in pages:
        fence = False
        for no, line in enumerate(open(page, encoding="utf-8"), 1):
            if line.startswith("```"):
                fence = not fence
            if fence:
                continue
            for m in LINK.finditer(line):
                link = m.group(1) or m.group(2)
                if re.match(r"^(https?|mailto):", link):
                    continue
                path, _, anchor = link.partition("#")
                target = os.path.normpath(os.path.join(os.path.dirname(page), path)) if path else page
                why = None
                if not os.path.exists(target):
                    why = "no such file"
                elif anchor and target.endswith(".md") and anchor not in anchors(target):
                    why = "no such heading"
                if why:
                    print(f"{os.path.relpath(page, root)}:{no}: {link}: {why}")
                    bad += 1
    print(f"check_links: {len(pages)} pages, {bad} broken link(s)")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
