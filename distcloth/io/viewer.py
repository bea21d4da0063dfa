"""``distcloth view``: one self-contained HTML page that plays a result.

The page holds everything it needs, so it opens from a file or a mail
attachment with no network: three.js and its OrbitControls (Debian's
libjs-three, r111, read from /usr/share/javascript/three or
``DISTCLOTH_THREE_DIR``) are copied into it, and so are the picked frames
(float32, base64) with the colliders' surfaces.  three.js rather than an
own WebGL renderer: lighting, normals, orbit controls and resizing come
tested, and the Debian package keeps the setup offline.

The page's script is io/viewer.js; ``#frame=K`` in the URL picks the first
frame shown, and the element ``#status`` says ``ok frame=K frames=N`` or
``error: ...``.
"""
from __future__ import annotations

import base64
import json
import os

import numpy as np

from ..config.schema import ConfigError
from .export import check_writable, write_atomic
from .frames import ResultFrames, parse_frames

THREE_DIR = "/usr/share/javascript/three"
THREE_FILES = ("three.min.js", "examples/js/controls/OrbitControls.js")
PLAY_FPS = 20.0

_PAGE = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>distcloth: {title}</title>
<style>
html, body {{ margin: 0; height: 100%; overflow: hidden; font: 13px sans-serif; }}
canvas {{ display: block; }}
#ui {{ position: absolute; left: 0; right: 0; bottom: 0; display: flex; gap: 10px;
       align-items: center; padding: 6px 10px; background: rgba(255, 255, 255, 0.8); }}
#slider {{ flex: 1; }}
#status {{ position: absolute; top: 4px; left: 8px; color: #555; }}
#status.error {{ color: #b00; font-weight: bold; }}
</style></head>
<body>
<div id="status">loading</div>
<div id="ui"><button id="play">play</button><input id="slider" type="range" min="0" max="0"
 value="0" step="1"><span id="label"></span></div>
{scripts}
</body></html>
"""


def _b64(array: np.ndarray, dtype: str) -> str:
    return base64.b64encode(np.ascontiguousarray(array, dtype=dtype).tobytes()).decode("ascii")


def _script(text: str, kind: str = "") -> str:
    # '</script' inside the text would end the element early; '<\\/' means the same in JS
    text = text.replace("</script", "<\\/script")
    return f"<script{kind}>\n{text}\n</script>"


def three_sources(folder: str | None = None) -> list[str]:
    """The vendored three.js scripts' texts; ConfigError when they are missing."""
    folder = folder or os.environ.get("DISTCLOTH_THREE_DIR", THREE_DIR)
    texts = []
    for name in THREE_FILES:
        path = os.path.join(folder, name)
        try:
            with open(path, encoding="utf-8") as handle:
                texts.append(handle.read())
        except OSError:
            raise ConfigError("view", path, "three.js r111 from Debian's libjs-three "
                                            "(scripts/setup.sh installs it)") from None
    return texts


def page_data(res: ResultFrames, frames: np.ndarray) -> dict:
    """What the page's script reads: the picked frames and the colliders."""
    positions = np.stack([res.positions(k) for k in frames]).astype(np.float32)
    colliders = []
    for name, body in res.colliders(frames).items():
        colliders.append({"name": name, "moving": bool(body["moving"]),
                          "vertices": int(body["positions"].shape[1]),
                          "triangles": _b64(body["triangles"], "<u4"),
                          "positions": _b64(body["positions"], "<f4")})
    return {"scene": res.scene, "vertices": res.n_vertices, "fps": PLAY_FPS,
            "frames": [int(k) for k in frames], "times": [float(res.time[k]) for k in frames],
            "triangles": _b64(res.triangles, "<u4"), "positions": _b64(positions, "<f4"),
            "colliders": colliders}


def page_html(data: dict, three: list[str]) -> str:
    here = os.path.dirname(os.path.abspath(__file__))
    with open(os.path.join(here, "viewer.js"), encoding="utf-8") as handle:
        viewer = handle.read()
    # '<' escaped: the JSON sits inside a script element
    payload = json.dumps(data, separators=(",", ":")).replace("<", "\\u003c")
    scripts = "\n".join([_script(t) for t in three]
                        + [f'<script id="data" type="application/json">{payload}</script>',
                           _script(viewer)])
    title = (data["scene"] or "result").replace("&", "&amp;").replace("<", "&lt;")
    return _PAGE.format(title=title, scripts=scripts)


def write_viewer(result: str, output: str | None = None, frames_spec: str = "all",
                 overwrite: bool = False) -> str:
    """Write the page for a result file; returns its path.  ConfigError for
    bad arguments, before anything is written."""
    out = output or os.path.splitext(result)[0] + ".html"
    if not out.lower().endswith((".html", ".htm")):
        raise ConfigError("--output", output, "a file name ending in .html")
    three = three_sources()
    with ResultFrames(result) as res:
        frames = parse_frames(frames_spec, res.n_frames)
        check_writable([out], overwrite)
        html = page_html(page_data(res, frames), three)
    write_atomic(out, [html.encode("utf-8")])
    return out
