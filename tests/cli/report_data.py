"""report_data.py — reads the data a `lumosaic report` page embeds (for tests/cli/report*.sh).
What it is: load(path) -> the page's JSON; cube(d, key) -> the embedded cube (recon or truth)
as floats, c[b][y][x]; png_size(url) -> (width, height) of a data:image/png URL; no_network(html)
-> the first thing that would load from a network, or None. What it is not: a test by itself."""
import base64, json, re, struct

MARK = '<script type="application/json" id="lm-data">'


def load(path):
    html = open(path, encoding="utf-8").read()
    a = html.index(MARK) + len(MARK)
    return json.loads(html[a:html.index("</script>", a)])


def cube(d, key):
    c = d["cube"]
    raw = base64.b64decode(c[key])
    w, h = c["w"], c["h"]
    assert len(raw) == 2 * 31 * w * h, (len(raw), w, h)
    v = struct.unpack("<%dH" % (31 * w * h), raw)
    s = c["scale"] / 65535.0
    return [[[v[(b * h + y) * w + x] * s for x in range(w)] for y in range(h)] for b in range(31)]


def png_size(url):
    head = "data:image/png;base64,"
    assert url.startswith(head), url[:40]
    raw = base64.b64decode(url[len(head):])
    assert raw[:8] == b"\x89PNG\r\n\x1a\n" and raw[12:16] == b"IHDR", raw[:16]
    return struct.unpack(">II", raw[16:24])


def no_network(html):
    """Anything a browser would fetch from elsewhere: src/href to a URL, a <link>, CSS url() or
    @import to one, fetch / XMLHttpRequest / import() in the script."""
    pats = [r'(src|href)\s*=\s*["\']?\s*(https?:)?//', r"<link\b", r"url\(\s*['\"]?(https?:)?//",
            r"@import", r"\bfetch\s*\(", r"XMLHttpRequest", r"\bimport\s*\(", r"<iframe\b"]
    for p in pats:
        m = re.search(p, html, re.I)
        if m:
            return m.group(0)
    return None
