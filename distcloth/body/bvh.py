"""Biovision hierarchy (BVH) motion capture files: reading and forward kinematics.

A BVH file has two sections.  ``HIERARCHY`` nests joints (``ROOT``, ``JOINT``)
in braces, each with an ``OFFSET`` (its position in its parent's frame at
rest) and ``CHANNELS n name...`` (the per-frame values it reads, in the order
listed); an ``End Site`` has an ``OFFSET`` only and marks the tip of the last
bone of a chain.  ``MOTION`` gives ``Frames: F``, ``Frame Time: dt`` (seconds)
and F lines of values, one per channel of every joint in file order.

Conventions read here (those of the format's common writers and readers):

* rotation channels are angles in degrees about the parent-frame axes x, y, z
  (right handed) and compose in the order listed: for ``Zrotation Xrotation
  Yrotation`` the joint's local rotation is ``Rz @ Rx @ Ry`` applied to column
  vectors;
* position channels move the joint: its local translation is ``OFFSET`` plus
  the (x, y, z) position values, whatever their order among the channels, and
  the translation is applied after the rotation (``x_parent = T + R x``);
* the rest pose is every channel at zero: joints at their offsets, all
  rotations identity (for the CMU files, a T-pose).

End Sites become leaf joints named ``<parent>_end`` (no channels) because
their offsets give the direction of the last bone.  Lengths stay in the
file's units unless ``scale`` (metres per unit) is given: the reader applies
it to offsets and position channels, and ``BvhClip.scale`` records it.
Malformed files raise ``ValueError`` with one line naming the file line and
what was expected there.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

# CMU motion capture lengths: the ASF files declare ``length 0.45`` in inches,
# so one unit is 1/0.45 inch (0.0564 m); the BVH conversions keep those units.
CMU_SCALE = 0.0254 / 0.45

ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
_CHANNEL_NAMES = {name.lower(): name for name in ROTATION_CHANNELS + POSITION_CHANNELS}


@dataclass(frozen=True)
class BvhClip:
    """A parsed BVH clip: hierarchy, channel layout and per-frame local transforms.

    ``names``, ``parents`` (-1 for a root), ``offsets`` (J, 3) and
    ``end_site`` (J,) describe the hierarchy, parents before children; End
    Sites are the leaf joints named ``<parent>_end``.  ``channels[j]`` lists
    joint j's channel names in file order and ``channel_start[j]`` the column
    of its first value in a frame line.  ``rotations`` (F, J, 3, 3) are the
    local rotations, ``translations`` (F, J, 3) the local translations
    (``OFFSET`` plus position channels; for a root, its position).  Lengths
    are in the file's units times ``scale``.  Clips resampled by
    ``distcloth.body.clip`` keep the hierarchy; their ``frame_time`` is the
    sample spacing (NaN if the samples are not evenly spaced).
    """
    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    end_site: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    channel_start: np.ndarray
    frame_time: float
    rotations: np.ndarray
    translations: np.ndarray
    scale: float = 1.0

    @property
    def n_frames(self) -> int:
        return self.rotations.shape[0]

    @property
    def n_joints(self) -> int:
        return len(self.names)

    @property
    def duration(self) -> float:
        """Seconds from the first frame to the last."""
        return max(self.n_frames - 1, 0) * self.frame_time

    @property
    def root_translation(self) -> np.ndarray:
        """(F, 3) position of the first root joint in every frame."""
        return self.translations[:, 0]

    def index(self, name: str) -> int:
        return self.names.index(name)

    def children(self, j: int) -> np.ndarray:
        return np.flatnonzero(self.parents == j)


def axis_rotation(axis: int, degrees) -> np.ndarray:
    """(..., 3, 3) right-handed rotations by ``degrees`` about axis 0, 1 or 2 (x, y, z)."""
    a = np.radians(np.asarray(degrees, dtype=np.float64))
    c, s = np.cos(a), np.sin(a)
    out = np.zeros(a.shape + (3, 3))
    i, k = [(1, 2), (2, 0), (0, 1)][axis]
    out[..., axis, axis] = 1.0
    out[..., i, i] = c
    out[..., k, k] = c
    out[..., i, k] = -s
    out[..., k, i] = s
    return out


class _Tokens:
    """The hierarchy's tokens with their line numbers (braces split off)."""

    def __init__(self, lines: list[tuple[int, list[str]]], source: str, end_line: int, end_label: str):
        self.items = [(tok, n) for n, toks in lines for tok in toks]
        self.pos = 0
        self.source = source
        self.end_line = end_line
        self.end_label = end_label

    def error(self, expected: str, line: int | None = None, got: str | None = None) -> ValueError:
        if line is None:
            tok, line = self.peek()
            got = self.end_label if tok is None else repr(tok)
        return ValueError(f"{self.source}: line {line}: expected {expected}, got {got}")

    def peek(self) -> tuple[str | None, int]:
        if self.pos < len(self.items):
            return self.items[self.pos]
        return None, self.end_line

    def next(self, expected: str) -> tuple[str, int]:
        tok, line = self.peek()
        if tok is None:
            raise self.error(expected)
        self.pos += 1
        return tok, line

    def keyword(self, word: str) -> int:
        tok, line = self.peek()
        if tok is None or tok.upper() != word.upper():
            raise self.error(repr(word))
        self.pos += 1
        return line

    def number(self, expected: str) -> float:
        tok, line = self.next(expected)
        try:
            value = float(tok)
        except ValueError:
            raise self.error(expected, line, repr(tok)) from None
        if not np.isfinite(value):
            raise self.error(expected, line, repr(tok))
        return value

    def name_on_line(self, what: str) -> str:
        """The rest of the current line up to an opening brace: a joint name (may hold spaces)."""
        tok, line = self.peek()
        words = []
        while tok is not None and line == self.items[self.pos - 1][1] and tok != "{":
            words.append(tok)
            self.pos += 1
            tok, line = self.peek()
        if not words:
            raise self.error(f"a {what} name", self.items[self.pos - 1][1], "none")
        return " ".join(words)


class _Builder:
    def __init__(self):
        self.names: list[str] = []
        self.parents: list[int] = []
        self.offsets: list[tuple[float, float, float]] = []
        self.end_site: list[bool] = []
        self.channels: list[tuple[str, ...]] = []


def _parse_joint(tok: _Tokens, b: _Builder, name: str, parent: int, line: int, is_end: bool) -> None:
    if name in b.names:
        raise tok.error("a joint name not used before", line, repr(name))
    j = len(b.names)
    b.names.append(name)
    b.parents.append(parent)
    b.offsets.append(None)
    b.end_site.append(is_end)
    b.channels.append(())
    tok.keyword("{")
    has_channels = False
    while True:
        word, wline = tok.next("'OFFSET', 'CHANNELS', 'JOINT', 'End Site' or '}'")
        key = word.upper()
        if key == "}":
            break
        if key == "OFFSET":
            if b.offsets[j] is not None:
                raise tok.error("one OFFSET per joint", wline, "a second OFFSET")
            b.offsets[j] = tuple(tok.number("a number (OFFSET x y z)") for _ in range(3))
        elif key == "CHANNELS" and not is_end:
            if has_channels:
                raise tok.error("one CHANNELS line per joint", wline, "a second CHANNELS")
            has_channels = True
            count_tok, cline = tok.next("a channel count")
            if not count_tok.isdigit():
                raise tok.error("a channel count (a non-negative integer)", cline, repr(count_tok))
            names = []
            for _ in range(int(count_tok)):
                ch, chline = tok.next(f"{count_tok} channel names")
                canonical = _CHANNEL_NAMES.get(ch.lower())
                if canonical is None:
                    raise tok.error("a channel name (X/Y/Z followed by position or rotation)", chline, repr(ch))
                if canonical in names:
                    raise tok.error("each channel at most once per joint", chline, f"{ch!r} again")
                names.append(canonical)
            b.channels[j] = tuple(names)
        elif key == "JOINT" and not is_end:
            child = tok.name_on_line("joint")
            _parse_joint(tok, b, child, j, wline, False)
        elif key == "END" and not is_end:
            site, sline = tok.next("'Site'")
            if site.upper() != "SITE":
                raise tok.error("'Site' after 'End'", sline, repr(site))
            base = f"{name}_end"
            end_name, k = base, 1
            while end_name in b.names:
                end_name, k = f"{base}{k}", k + 1
            _parse_joint(tok, b, end_name, j, wline, True)
        else:
            expected = "'OFFSET' or '}' in an End Site" if is_end else "'OFFSET', 'CHANNELS', 'JOINT', 'End Site' or '}'"
            raise tok.error(expected, wline, repr(word))
    if b.offsets[j] is None:
        raise tok.error(f"an OFFSET in {name!r} before its closing brace", line, "none")


_FRAMES = re.compile(r"^frames\s*:\s*(\S+)$", re.IGNORECASE)
_FRAME_TIME = re.compile(r"^frame\s+time\s*:\s*(\S+)$", re.IGNORECASE)


def parse_bvh(text: str, scale: float = 1.0, source: str = "<bvh>") -> BvhClip:
    """Parse BVH text; lengths are multiplied by ``scale`` (metres per file unit)."""
    if not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"{source}: scale must be a positive number, got {scale!r}")
    lines = text.splitlines()
    motion_at = None
    hierarchy = []
    for n, line in enumerate(lines, start=1):
        toks = line.replace("{", " { ").replace("}", " } ").split()
        if toks and toks[0].upper() == "MOTION":
            if len(toks) > 1:
                raise ValueError(f"{source}: line {n}: expected 'MOTION' alone on its line, got {line.strip()!r}")
            motion_at = n
            break
        if toks:
            hierarchy.append((n, toks))
    if motion_at is None:
        tok = _Tokens(hierarchy, source, max(len(lines), 1), "end of file")
    else:
        tok = _Tokens(hierarchy, source, motion_at, "'MOTION'")
    tok.keyword("HIERARCHY")
    b = _Builder()
    while tok.peek()[0] is not None:
        word, line = tok.peek()
        if word.upper() != "ROOT":
            raise tok.error("'ROOT'" if not b.names else "'ROOT' or 'MOTION'")
        tok.pos += 1
        _parse_joint(tok, b, tok.name_on_line("root"), -1, line, False)
    if not b.names:
        raise tok.error("'ROOT'")
    if motion_at is None:
        raise ValueError(f"{source}: line {len(lines)}: expected 'MOTION', got end of file")

    rest = [(n, line.strip()) for n, line in enumerate(lines[motion_at:], start=motion_at + 1) if line.strip()]

    def header(i, pattern, expected):
        if i >= len(rest):
            raise ValueError(f"{source}: line {len(lines)}: expected {expected}, got end of file")
        n, line = rest[i]
        m = pattern.match(line)
        if m is None:
            raise ValueError(f"{source}: line {n}: expected {expected}, got {line[:40]!r}")
        return n, m.group(1)

    n, value = header(0, _FRAMES, "'Frames: <count>'")
    if not value.isdigit():
        raise ValueError(f"{source}: line {n}: expected a non-negative integer frame count, got {value!r}")
    n_frames = int(value)
    n, value = header(1, _FRAME_TIME, "'Frame Time: <seconds>'")
    try:
        frame_time = float(value)
    except ValueError:
        frame_time = float("nan")
    if not (np.isfinite(frame_time) and (frame_time > 0 or (frame_time == 0 and n_frames <= 1))):
        raise ValueError(f"{source}: line {n}: expected a positive frame time in seconds, got {value!r}")

    counts = [len(c) for c in b.channels]
    n_channels = sum(counts)
    data = np.zeros((n_frames, n_channels))
    body = rest[2:]
    for f in range(n_frames):
        if f >= len(body):
            raise ValueError(f"{source}: line {len(lines) + 1}: expected frame {f + 1} of {n_frames} "
                             f"({n_channels} values), got end of file")
        n, line = body[f]
        values = line.split()
        if len(values) != n_channels:
            raise ValueError(f"{source}: line {n}: expected {n_channels} values (frame {f + 1}), got {len(values)}")
        try:
            data[f] = np.array(values, dtype=np.float64)
        except ValueError:
            raise ValueError(f"{source}: line {n}: expected {n_channels} numbers (frame {f + 1}), "
                             f"got a value that is not a number") from None
        if not np.all(np.isfinite(data[f])):
            raise ValueError(f"{source}: line {n}: expected finite numbers (frame {f + 1}), got inf or nan")
    if len(body) > n_frames:
        n, _ = body[n_frames]
        raise ValueError(f"{source}: line {n}: expected end of file after {n_frames} frames, got more values")
    return _clip_from_channels(b, data, frame_time, scale)


def _clip_from_channels(b: _Builder, data: np.ndarray, frame_time: float, scale: float) -> BvhClip:
    n_frames, n_joints = data.shape[0], len(b.names)
    offsets = np.array(b.offsets, dtype=np.float64) * scale
    starts = np.concatenate([[0], np.cumsum([len(c) for c in b.channels])[:-1]]).astype(np.int64)
    rotations = np.broadcast_to(np.eye(3), (n_frames, n_joints, 3, 3)).copy()
    translations = np.broadcast_to(offsets, (n_frames, n_joints, 3)).copy()
    for j, names in enumerate(b.channels):
        for k, ch in enumerate(names):
            column = data[:, starts[j] + k]
            if ch in ROTATION_CHANNELS:
                rotations[:, j] = rotations[:, j] @ axis_rotation(ROTATION_CHANNELS.index(ch), column)
            else:
                translations[:, j, POSITION_CHANNELS.index(ch)] += scale * column
    return BvhClip(
        names=tuple(b.names), parents=np.array(b.parents, dtype=np.int64), offsets=offsets,
        end_site=np.array(b.end_site, dtype=bool), channels=tuple(b.channels), channel_start=starts,
        frame_time=frame_time, rotations=rotations, translations=translations, scale=float(scale))


def read_bvh(path, scale: float = 1.0) -> BvhClip:
    """Read a BVH file; lengths are multiplied by ``scale`` (metres per file unit,
    ``CMU_SCALE`` for the CMU conversions)."""
    path = Path(path)
    return parse_bvh(path.read_text(encoding="utf-8", errors="replace"), scale=scale, source=str(path))


def bvh_global(clip: BvhClip, frames=None) -> tuple[np.ndarray, np.ndarray]:
    """Forward kinematics: global rotations (F, J, 3, 3) and joint positions (F, J, 3).

    ``frames`` selects frames (an index array or slice; all by default).  A
    joint's global rotation is its parent's times its local rotation, its
    position its parent's plus the parent's global rotation applied to its
    local translation.  The rotations are relative to the rest pose (all
    channels zero), where every global rotation is the identity.
    """
    sel = slice(None) if frames is None else frames
    local_r = clip.rotations[sel]
    local_t = clip.translations[sel]
    rot = np.empty_like(local_r)
    pos = np.empty_like(local_t)
    for j, p in enumerate(clip.parents):
        if p < 0:
            rot[:, j] = local_r[:, j]
            pos[:, j] = local_t[:, j]
        else:
            rot[:, j] = rot[:, p] @ local_r[:, j]
            pos[:, j] = pos[:, p] + np.einsum("fab,fb->fa", rot[:, p], local_t[:, j])
    return rot, pos


def rest_positions(clip: BvhClip) -> np.ndarray:
    """(J, 3) joint positions at the rest pose (all channels zero: roots at their offsets)."""
    pos = np.empty_like(clip.offsets)
    for j, p in enumerate(clip.parents):
        pos[j] = clip.offsets[j] if p < 0 else pos[p] + clip.offsets[j]
    return pos
