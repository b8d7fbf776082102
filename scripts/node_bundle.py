"""What must travel to an offline GPU node, built on a machine that reaches PyPI (docs/gpu.md, `make node-bundle`):

    .venv/bin/python scripts/node_bundle.py build        # download, check, pack, split -> .node/parts/; the plan
    .venv/bin/python scripts/node_bundle.py check [DIR]  # the wheels in DIR against the node's package list
    .venv/bin/python scripts/node_bundle.py plan [--without pretrained]   # the calls for the tree as it is now
    .venv/bin/python scripts/node_bundle.py clips DIR    # copy the clip files out of pybullet_data

The node (one NVIDIA H200) has Python 3.12 with its own CUDA torch and the packages listed in
scripts/node_packages.txt, reaches no registry, and takes files only through transfers of at most 64 MiB
each, the working tree included; between calls sent within 30 s of each other it keeps git-ignored files.

1. Wheels: ROOTS (what the GPU path imports and the node lacks, at the versions installed in this .venv,
   i.e. the ones `make test` ran) and everything they require, found by reading each wheel's METADATA
   Requires-Dist (markers evaluated for CPython 3.12 on x86-64 Linux, extras followed) and checking each
   requirement against the node's list (`closure`). Each one missing is fetched with `pip download
   --no-deps --only-binary=:all: --python-version 3.12 --implementation cp --platform manylinux_2_28_x86_64
   ...`; one with no wheel at all that is pure Python (antlr4-python3-runtime 4.9.3, which hydra-core pins, is
   a source archive only) is built here into a py3-none-any wheel. The check fails on a requirement met
   neither by the node nor by a wheel, on a version that the node's known one or the wheel does not
   satisfy, on a wheel whose tags or Requires-Python do not fit the node, on two versions of one package.
2. Clips: the catalogue's DeepMimic clips and humanoid.urdf copied out of pybullet_data (pybullet has no
   wheel; on the node charctl reads them from CHARCTL_CLIP_DIR).
3. One archive, split. Decision for warp-lang (a 149 MB wheel: 285 MiB of warp.so deflated to 110 MiB):
   send it in parts over consecutive calls, after re-zipping every wheel uncompressed (the same files and
   RECORD, so pip installs it as it is) and packing the whole staging folder as one tar.xz at preset 9e
   with a 384 MiB dictionary (one that spans warp.so), which takes warp.so to 59 MiB. Rejected: building
   warp.so for sm_90 on the node with its nvcc (Warp's native build also needs its LLVM/Clang toolchain
   and takes longer than the node's 15 minutes, and would be a different binary from the one the tests
   ran), JAX's MJX (another simulator API; charctl's device env is written against MuJoCo Warp, a port
   would need its own parity work), dropping warp-clang.so (Warp's CPU kernels: ~15 MiB less, at the risk
   of a code path that touches Warp's CPU device). The archive is split into the fewest parts of at most
   (64 MiB - working tree - 1 MiB), evened out.
4. The plan: one device call per part, each carrying .node/parts/manifest.json and its part; every call
   runs `python3 scripts/node_run.py receive` (which moves the part into .node/recv/), the last one also
   `python3 scripts/node_run.py run` (scripts/node_run.py: install, parity, bench, time-boxed paper run).
"""

from __future__ import annotations

import argparse
import email.parser
import hashlib
import importlib.metadata as md
import json
import lzma
import os
import shutil
import stat
import subprocess
import sys
import tarfile
import tempfile
import time
import zipfile
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

from packaging.requirements import Requirement
from packaging.specifiers import SpecifierSet
from packaging.tags import Tag, compatible_tags, cpython_tags
from packaging.utils import InvalidWheelFilename, canonicalize_name, parse_wheel_filename

REPO = Path(__file__).resolve().parent.parent
MiB = 1 << 20
TRANSFER_LIMIT = 64 * MiB  # one device call: tracked + untracked-not-ignored files + carried paths
MARGIN = 1 * MiB  # room for the tree to grow between the build and the last call (and the manifest)
NODE_PACKAGES = REPO / "scripts" / "node_packages.txt"
CACHE = Path(os.environ.get("CHARCTL_NODE_CACHE", "/tmp/charctl-node"))  # downloads, staging, the archive
NODE_DIR = REPO / ".node"  # git-ignored: what the device calls carry (parts/) and what the node writes
PARTS = NODE_DIR / "parts"
# What the GPU path (cgail with env.backend=warp, its tests, bench and eval) imports that the node lacks.
ROOTS = ("mujoco-warp", "mujoco", "warp-lang", "hydra-core", "omegaconf", "dtw-python", "array-api-compat")
# pip matches a manylinux tag exactly: every glibc level up to the node's target, oldest names last.
PLATFORMS = tuple(f"manylinux_2_{n}_x86_64" for n in range(28, 16, -1)) + ("manylinux2014_x86_64", "manylinux1_x86_64")
# The real bundle's archive as `build` made it (12 wheels + 21 clip files), for the plan's test.
MEASURED_ARCHIVE_BYTES = 100_623_328  # 96.0 MiB (wheels 170.8 MiB as downloaded; xz 9e, 384 MiB dictionary)
RUN_BUDGET_S = 540  # the measuring command's own time box (one device command: at most 600 s)


# ----------------------------------------------------------------------------------------- the node
@dataclass
class Target:
    """The interpreter and packages that the wheels must install into."""

    python: str = "3.12.3"
    packages: dict[str, str | None] = field(default_factory=dict)  # canonical name -> version (None: unknown)
    platforms: tuple[str, ...] = PLATFORMS

    @property
    def python_short(self) -> str:
        return ".".join(self.python.split(".")[:2])

    def markers(self) -> dict[str, str]:
        return {
            "implementation_name": "cpython",
            "implementation_version": self.python,
            "os_name": "posix",
            "platform_machine": "x86_64",
            "platform_python_implementation": "CPython",
            "platform_release": "",
            "platform_system": "Linux",
            "platform_version": "",
            "python_full_version": self.python,
            "python_version": self.python_short,
            "sys_platform": "linux",
        }

    def tags(self) -> set[Tag]:
        major, minor = (int(x) for x in self.python.split(".")[:2])
        interp = f"cp{major}{minor}"
        return set(cpython_tags((major, minor), abis=[interp], platforms=list(self.platforms))) | set(
            compatible_tags((major, minor), interp, platforms=list(self.platforms))
        )


def load_node_packages(path: Path = NODE_PACKAGES) -> Target:
    """scripts/node_packages.txt: `name` or `name==version` per line; `# python: X.Y.Z` names the interpreter."""
    target = Target()
    for raw in path.read_text().splitlines():
        line = raw.strip()
        if line.startswith("# python:"):
            target.python = line.split(":", 1)[1].strip()
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        name, _, version = line.partition("==")
        target.packages[canonicalize_name(name)] = version.strip() or None
    return target


def installed_target(python: str | None = None) -> Target:
    """The running interpreter's own packages as a Target (the node's real set, when run there)."""
    packages: dict[str, str | None] = {}
    for dist in md.distributions():
        name = dist.metadata["Name"]
        if name:
            packages.setdefault(canonicalize_name(name), dist.version)
    return Target(python=python or ".".join(map(str, sys.version_info[:3])), packages=packages)


# --------------------------------------------------------------------------------------- metadata
@dataclass(frozen=True)
class Meta:
    """The parts of a wheel's METADATA the closure needs."""

    name: str  # canonical
    version: str
    requires_python: str | None
    requires: tuple[str, ...]
    file: str | None = None


def parse_metadata(text: str, file: str | None = None) -> Meta:
    msg = email.parser.Parser().parsestr(text, headersonly=True)
    return Meta(
        canonicalize_name(msg["Name"]),
        str(msg["Version"]),
        msg.get("Requires-Python"),
        tuple(msg.get_all("Requires-Dist") or ()),
        file,
    )


def wheel_metadata(path: Path) -> Meta:
    with zipfile.ZipFile(path) as z:
        names = [n for n in z.namelist() if n.count("/") == 1 and n.endswith(".dist-info/METADATA")]
        if not names:
            raise ValueError(f"{path.name}: no .dist-info/METADATA")
        return parse_metadata(z.read(names[0]).decode("utf-8"), file=path.name)


def dist_metadata(dist: md.Distribution) -> Meta:
    """An installed distribution's METADATA (or an egg's PKG-INFO) as a Meta."""
    m = dist.metadata
    return Meta(canonicalize_name(m["Name"]), str(m["Version"]), m.get("Requires-Python"), tuple(dist.requires or ()))


def local_metadata(name: str) -> Meta | None:
    """This interpreter's installed copy of `name` (used for the extras of a package the node has)."""
    try:
        return dist_metadata(md.distribution(name))
    except md.PackageNotFoundError:
        return None


def local_version(name: str) -> str | None:
    try:
        return md.version(name)
    except md.PackageNotFoundError:
        return None


# ---------------------------------------------------------------------------------------- closure
@dataclass
class Closure:
    bundled: dict[str, Meta] = field(default_factory=dict)  # wheels reached from the roots
    on_node: dict[str, list[str]] = field(default_factory=dict)  # node packages reached, and by what
    missing: list[tuple[Requirement, str]] = field(default_factory=list)  # (requirement, required by)
    conflicts: list[str] = field(default_factory=list)
    unverified: list[str] = field(default_factory=list)  # met by name only: the node's version is not known
    notes: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)  # wheel files: tags, Requires-Python, duplicates
    unused: list[str] = field(default_factory=list)  # wheels given but not reached

    @property
    def ok(self) -> bool:
        return not (self.missing or self.conflicts or self.problems)

    def pins(self) -> list[str]:
        return [f"{m.name}=={m.version}" for m in sorted(self.bundled.values(), key=lambda m: m.name)]

    def lines(self) -> list[str]:
        out = [
            f"closure: {len(self.bundled)} wheels to bundle, {len(self.on_node)} requirements met by the node: "
            + ("complete" if self.ok else "INCOMPLETE"),
            "  bundle: " + ", ".join(self.pins()),
            "  on the node: " + ", ".join(sorted(self.on_node)),
        ]
        out += [f"  missing: {r} (required by {by})" for r, by in self.missing]
        out += [f"  conflict: {c}" for c in self.conflicts]
        out += [f"  wheel problem: {p}" for p in self.problems]
        out += [f"  unverified: {u}" for u in self.unverified]
        out += [f"  note: {n}" for n in self.notes]
        out += [f"  unused wheel: {u}" for u in self.unused]
        return out


def _applies(req: Requirement, env: dict[str, str], extras: Iterable[str]) -> bool:
    if req.marker is None:
        return True
    return any(req.marker.evaluate({**env, "extra": e}) for e in ("", *extras))


def closure(
    roots: Iterable[str | Requirement],
    wheels: dict[str, Meta],
    target: Target,
    proxy: Callable[[str], Meta | None] | None = None,
) -> Closure:
    """Follow the roots' Requires-Dist through `wheels` (canonical name -> METADATA) and the node's packages.

    A requirement the node meets (by its known version, or by name when the version is unknown) is not
    bundled; the extras of such a package are checked through `proxy` (another copy of its METADATA,
    e.g. this machine's installed one). A bundled wheel's requirements are followed with the extras asked
    for. The node's package wins over a wheel of the same name unless its known version does not fit.
    """
    c = Closure()
    env = target.markers()
    queue: list[tuple[Requirement, str]] = []
    for r in roots:
        req = r if isinstance(r, Requirement) else Requirement(r)
        if _applies(req, env, ()):
            queue.append((req, "the roots"))
    seen: set[tuple[str, frozenset[str]]] = set()
    while queue:
        req, by = queue.pop(0)
        name = canonicalize_name(req.name)
        extras = frozenset(req.extras)
        label = f"{req} (required by {by})"
        wheel = wheels.get(name)
        on_node = name in target.packages
        node_version = target.packages.get(name)
        node_fits = node_version is None or req.specifier.contains(node_version, prereleases=True)
        if on_node and (node_fits or wheel is None):
            c.on_node.setdefault(name, []).append(label)
            if not node_fits:
                c.conflicts.append(f"{label}: the node has {name} {node_version}")
            elif node_version is None and req.specifier:
                c.unverified.append(f"{label}: the node's version of {name} is not known here")
            if extras and (name, extras) not in seen:
                seen.add((name, extras))
                meta = proxy(name) if proxy else None
                if meta is None:
                    c.unverified.append(f"{label}: the extras of the node's {name} are not checked (no METADATA)")
                    continue
                for r in meta.requires:
                    dep = Requirement(r)
                    if _applies(dep, env, extras) and not _applies(dep, env, ()):
                        queue.append((dep, f"{name}[{','.join(sorted(extras))}]"))
            continue
        if wheel is None:
            c.missing.append((req, by))
            continue
        if not req.specifier.contains(wheel.version, prereleases=True):
            c.conflicts.append(f"{label}: the bundled wheel is {name} {wheel.version}")
        if on_node:
            c.notes.append(
                f"{name}: the node's {node_version} does not satisfy {req}; the wheel {wheel.version} shadows it"
            )
        if (name, extras) in seen:
            continue
        first = name not in c.bundled
        seen.add((name, extras))
        c.bundled[name] = wheel
        for r in wheel.requires:
            dep = Requirement(r)
            if _applies(dep, env, extras) and (first or not _applies(dep, env, ())):
                queue.append((dep, f"{name} {wheel.version}"))
    c.unused = sorted(m.file or m.name for n, m in wheels.items() if n not in c.bundled)
    return c


def check_wheels(paths: Iterable[Path], target: Target) -> tuple[dict[str, Meta], list[str]]:
    """Read every wheel's METADATA; list those that cannot install on the target (tags, Requires-Python, twins)."""
    tags = target.tags()
    wheels: dict[str, Meta] = {}
    problems: list[str] = []
    for path in sorted(paths):
        try:
            name, version, _build, wtags = parse_wheel_filename(path.name)
        except InvalidWheelFilename as exc:
            problems.append(f"{path.name}: {exc}")
            continue
        if not wtags & tags:
            problems.append(
                f"{path.name}: none of its tags installs on CPython {target.python_short} {target.platforms[0]}"
            )
        meta = wheel_metadata(path)
        if meta.requires_python and not SpecifierSet(meta.requires_python).contains(target.python, prereleases=True):
            problems.append(f"{path.name}: Requires-Python {meta.requires_python} excludes {target.python}")
        if name in wheels:
            problems.append(f"two versions of {name}: {wheels[name].file} and {path.name} (pip stops on both)")
        wheels[name] = meta
    return wheels, problems


def check_dir(wheel_dir: Path, roots: Iterable[str], target: Target) -> Closure:
    wheels, problems = check_wheels(wheel_dir.glob("*.whl"), target)
    c = closure(roots, wheels, target, proxy=local_metadata)
    c.problems += problems
    return c


def default_roots() -> list[str]:
    """ROOTS pinned to the versions installed here (the ones this machine's tests ran)."""
    return [f"{n}=={v}" if (v := local_version(n)) else n for n in ROOTS]


# --------------------------------------------------------------------------------------- download
def _pip() -> list[str]:
    return [sys.executable, "-m", "pip"]


def pip_download(spec: str, dest: Path, target: Target, log: list[str]) -> bool:
    plat = [a for p in target.platforms for a in ("--platform", p)]
    cmd = [*_pip(), "download", "-q", "--no-deps", "--only-binary=:all:", "--python-version", target.python_short]
    cmd += ["--implementation", "cp", *plat, "-d", str(dest), spec]
    res = subprocess.run(cmd, capture_output=True, text=True)
    log.append(f"$ pip download {spec}: exit {res.returncode}")
    return res.returncode == 0


def pip_build_pure(spec: str, dest: Path, log: list[str]) -> bool:
    """A package with no wheel on the index: build one here, accepted only when it is pure Python (none-any)."""
    with tempfile.TemporaryDirectory() as tmp:
        res = subprocess.run([*_pip(), "wheel", "-q", "--no-deps", "-w", tmp, spec], capture_output=True, text=True)
        built = list(Path(tmp).glob("*.whl"))
        pure = [
            w for w in built if all(t.abi == "none" and t.platform == "any" for t in parse_wheel_filename(w.name)[3])
        ]
        log.append(f"$ pip wheel {spec} (no wheel on the index): exit {res.returncode}, pure: {[w.name for w in pure]}")
        for w in pure:
            shutil.copy2(w, dest / w.name)
        return bool(pure)


def resolve(roots: list[str], wheel_dir: Path, target: Target, log: list[str]) -> Closure:
    """Download what the closure misses until nothing new can be fetched; return the final check."""
    wheel_dir.mkdir(parents=True, exist_ok=True)
    tried: set[str] = set()
    while True:
        c = check_dir(wheel_dir, roots, target)
        todo = []
        for req, _by in c.missing:
            name = canonicalize_name(req.name)
            have = local_version(name)
            fits = have is not None and req.specifier.contains(have, prereleases=True)
            spec = f"{name}=={have}" if fits else f"{name}{req.specifier}"
            if spec not in tried and spec not in todo:
                todo.append(spec)
        if not todo:
            return c
        for spec in todo:
            tried.add(spec)
            if not pip_download(spec, wheel_dir, target, log):
                pip_build_pure(spec, wheel_dir, log)


# -------------------------------------------------------------------------------------- packaging
def sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(MiB):
            h.update(block)
    return h.hexdigest()


def repack_stored(src: Path, dst: Path) -> None:
    """The same wheel (names, contents, permissions, RECORD) as an uncompressed zip, which xz packs far better."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_STORED) as zout:
        for info in zin.infolist():
            out = zipfile.ZipInfo(info.filename, info.date_time)
            out.external_attr, out.create_system, out.file_size = info.external_attr, info.create_system, info.file_size
            out.compress_type = zipfile.ZIP_STORED
            with zin.open(info) as f, zout.open(out, "w") as g:
                shutil.copyfileobj(f, g, MiB)
    with zipfile.ZipFile(src) as a, zipfile.ZipFile(dst) as b:
        if [(i.filename, i.CRC, i.file_size) for i in a.infolist()] != [
            (i.filename, i.CRC, i.file_size) for i in b.infolist()
        ]:
            raise RuntimeError(f"re-zipping {src.name} changed its contents")


def copy_clips(dst: Path) -> list[str]:
    """The catalogue's clips and humanoid.urdf, laid out as in pybullet_data (the CHARCTL_CLIP_DIR layout)."""
    from charctl.motion.library import catalogue, motions_dir
    from charctl.motion.skeleton import humanoid_urdf_path

    files = [(motions_dir() / e.file, Path("data") / "motions" / e.file) for e in catalogue()]
    files.append((humanoid_urdf_path(), Path("humanoid") / "humanoid.urdf"))
    for src, rel in files:
        (dst / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src, dst / rel)
    return [str(rel) for _, rel in files]


def _preset(text: str) -> int:
    return int(text.rstrip("e")) | (lzma.PRESET_EXTREME if text.endswith("e") else 0)


def make_archive(stage: Path, archive: Path, preset: str = "9e", dict_mib: int = 0) -> None:
    """stage/ as one tar.xz, entries sorted and with neutral owners and times (the same input, the same bytes).

    dict_mib > 0 sets LZMA2's dictionary (the preset's own: 64 MiB at 9): one that spans warp.so (285 MiB)
    finds what its per-architecture GPU code repeats far apart, 59 MiB for it instead of 74 (packing needs
    ~11 x the dictionary in memory, unpacking 1 x)."""

    def neutral(ti: tarfile.TarInfo) -> tarfile.TarInfo:
        ti.uid = ti.gid = 0
        ti.uname = ti.gname = ""
        ti.mtime = 0
        return ti

    tmp = archive.with_suffix(".partial")
    lzma2: dict = {"id": lzma.FILTER_LZMA2, "preset": _preset(preset)}
    if dict_mib:
        lzma2["dict_size"] = dict_mib * MiB
    with lzma.open(tmp, "wb", format=lzma.FORMAT_XZ, filters=[lzma2]) as xz, tarfile.open(fileobj=xz, mode="w|") as tf:
        for path in sorted(p for p in stage.rglob("*") if p.is_file()):
            tf.add(path, arcname=str(path.relative_to(stage)), filter=neutral)
    os.replace(tmp, archive)


def split(archive: Path, out_dir: Path, part_bytes: int) -> list[dict]:
    """Cut the archive into consecutive parts of at most part_bytes (old parts are removed first)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    for old in out_dir.glob("part-*"):
        old.unlink()
    parts = []
    with open(archive, "rb") as f:
        while chunk := f.read(part_bytes):
            name = f"part-{len(parts) + 1}"
            (out_dir / name).write_bytes(chunk)
            parts.append({"name": name, "bytes": len(chunk), "sha256": hashlib.sha256(chunk).hexdigest()})
    return parts


# ---------------------------------------------------------------------------------- transfer plan
def tree_files(repo: Path = REPO) -> dict[str, int]:
    """What a device call sends besides `carry`: tracked and untracked-not-ignored files, and shared/."""
    cmd = ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"]
    out = subprocess.run(cmd, cwd=repo, capture_output=True, check=True).stdout.decode()
    rels = [r for r in out.split("\0") if r]
    if (repo / "shared").is_dir():
        rels += [str(p.relative_to(repo)) for p in (repo / "shared").rglob("*") if not p.is_dir()]
    sizes = {}
    for rel in rels:
        try:
            st = os.lstat(repo / rel)
        except FileNotFoundError:  # a tracked file deleted in the working tree
            continue
        if stat.S_ISREG(st.st_mode) or stat.S_ISLNK(st.st_mode):
            sizes[rel] = st.st_size
    return sizes


def without_folders(sizes: dict[str, int], without: Iterable[str] = ()) -> dict[str, int]:
    drop = tuple(w.rstrip("/") + "/" for w in without)
    return {rel: s for rel, s in sizes.items() if not rel.startswith(drop)} if drop else sizes


def tree_bytes(sizes: dict[str, int]) -> int:
    return sum(sizes.values())


def part_size(tree: int, limit: int = TRANSFER_LIMIT, margin: int = MARGIN) -> int:
    """The largest part (whole 64 KiB) that still fits one call next to the tree; an error when none is 1 MiB."""
    room = (limit - tree - margin) // (64 << 10) * (64 << 10)
    if room < MiB:
        raise SystemExit(
            f"error: the working tree alone is {tree / MiB:.1f} MiB of the {limit / MiB:.0f} MiB a call carries: "
            "ignore or remove what need not travel (`scripts/node_bundle.py plan` lists the largest folders)"
        )
    return room


def balanced(total: int, largest: int) -> int:
    """The part size that cuts `total` into the fewest parts of at most `largest`, all of about one size."""
    n = -(-total // largest)
    return -(-total // n)


def plan(tree: int, parts: list[dict], manifest_bytes: int, limit: int = TRANSFER_LIMIT, budget_s: int = RUN_BUDGET_S):
    """The device calls, in order: what each carries, its size, its command."""
    rel_parts = PARTS.relative_to(REPO)
    calls = []
    for i, p in enumerate(parts, 1):
        command = "python3 scripts/node_run.py receive"
        if i == len(parts):
            command += f" && python3 scripts/node_run.py run --budget {budget_s}"
        size = tree + manifest_bytes + p["bytes"]
        calls.append(
            {
                "call": i,
                "carry": [str(rel_parts / "manifest.json"), str(rel_parts / p["name"])],
                "bytes": size,
                "fits": size <= limit,
                "command": command,
                "timeout_s": 600 if i == len(parts) else 60,
            }
        )
    return calls


def largest_folders(sizes: dict[str, int], n: int = 5) -> list[tuple[str, int]]:
    by: dict[str, int] = {}
    for rel, s in sizes.items():
        key = rel.split("/")[0]
        by[key] = by.get(key, 0) + s
    return sorted(by.items(), key=lambda kv: -kv[1])[:n]


def print_plan(calls: list[dict], tree: int, sizes: dict[str, int]) -> None:
    big = ", ".join(f"{k} {v / MiB:.1f}" for k, v in largest_folders(sizes))
    print(f"working tree: {tree / MiB:.2f} MiB (largest, MiB: {big})")
    for c in calls:
        flag = "" if c["fits"] else "  <-- OVER THE LIMIT"
        carry = json.dumps(c["carry"])
        print(f"  call {c['call']}: {c['bytes'] / MiB:6.2f} MiB  carry={carry}  timeout_s={c['timeout_s']}")
        print(f"          {c['command']}{flag}")


# ------------------------------------------------------------------------------------------ build
def build(args: argparse.Namespace) -> int:
    target = load_node_packages()
    roots = default_roots()
    log: list[str] = []
    cache: Path = args.cache
    print(f"resolving {', '.join(roots)} for CPython {target.python} on {target.platforms[0]} (cache {cache})")
    c = resolve(roots, cache / "wheels", target, log)
    print("\n".join(log + c.lines()))
    if not c.ok:
        print("error: the wheel set is not complete for the node (see above)", file=sys.stderr)
        return 1
    stage = cache / "stage"
    shutil.rmtree(stage, ignore_errors=True)
    (stage / "wheels").mkdir(parents=True)
    wheels = []
    for meta in sorted(c.bundled.values(), key=lambda m: m.name):
        src = cache / "wheels" / str(meta.file)
        repack_stored(src, stage / "wheels" / src.name)
        size, digest = src.stat().st_size, sha256(src)
        wheels.append({"file": src.name, "name": meta.name, "version": meta.version, "bytes": size, "sha256": digest})
    clips = copy_clips(stage / "clips")
    bundle = {"install": c.pins(), "wheels": wheels, "clips": clips, "closure": c.lines(), "python": target.python}
    (stage / "bundle.json").write_text(json.dumps(bundle, indent=1))
    key = hashlib.sha256(json.dumps([wheels, clips, args.preset, args.dict_mib]).encode()).hexdigest()[:12]
    archive = cache / f"bundle-{key}.tar.xz"
    if archive.is_file():
        print(f"archive: {archive} (cached)")
    else:
        how = f"xz preset {args.preset}, dictionary {args.dict_mib or 'the preset'} MiB"
        print(f"packing {stage} into {archive} ({how}: minutes for warp.so) ...", flush=True)
        t1 = time.time()
        make_archive(stage, archive, args.preset, args.dict_mib)
        print(f"  packed in {time.time() - t1:.0f} s")
    return write_parts(archive, bundle, args.without)


def write_parts(archive: Path, bundle: dict, without: list[str]) -> int:
    sizes = without_folders(tree_files(), without)
    tree = tree_bytes(sizes)
    parts = split(archive, PARTS, balanced(archive.stat().st_size, part_size(tree)))
    manifest = {
        "format": 1,
        "archive": {"name": archive.name, "bytes": archive.stat().st_size, "sha256": sha256(archive)},
        "parts": parts,
        "install": bundle["install"],
        "wheels": bundle["wheels"],
        "clips": bundle["clips"],
        "tree_bytes_at_split": tree,
    }
    text = json.dumps(manifest, indent=1)
    (PARTS / "manifest.json").write_text(text)
    calls = plan(tree, parts, len(text))
    (NODE_DIR / "plan.json").write_text(json.dumps({"tree_bytes": tree, "without": without, "calls": calls}, indent=1))
    wheel_total = sum(w["bytes"] for w in bundle["wheels"])
    print(
        f"bundle: {len(bundle['wheels'])} wheels ({wheel_total / MiB:.1f} MiB as downloaded), {len(bundle['clips'])} "
        f"clip files -> {manifest['archive']['bytes'] / MiB:.1f} MiB archive in {len(parts)} parts under {PARTS}"
    )
    print_plan(calls, tree, sizes)
    if without:
        print(f"(planned without {', '.join(without)}: those must really stay out of the tree that travels)")
    return 0 if all(c["fits"] for c in calls) else 1


def cmd_plan(args: argparse.Namespace) -> int:
    """Re-plan for the tree as it is now: re-split the cached archive when the parts no longer fit."""
    manifest_path = PARTS / "manifest.json"
    sizes = without_folders(tree_files(), args.without)
    tree = tree_bytes(sizes)
    if not manifest_path.is_file():
        print(f"working tree: {tree / MiB:.2f} MiB -> parts of <= {part_size(tree) / MiB:.1f} MiB (no bundle yet)")
        return 0
    manifest = json.loads(manifest_path.read_text())
    calls = plan(tree, manifest["parts"], manifest_path.stat().st_size)
    if not all(c["fits"] for c in calls) or args.resplit:
        archive = args.cache / manifest["archive"]["name"]
        if not archive.is_file():
            print_plan(calls, tree, sizes)
            print(f"error: a part no longer fits and {archive} is gone: run build again", file=sys.stderr)
            return 1
        return write_parts(archive, manifest, args.without)
    print_plan(calls, tree, sizes)
    n = -(-manifest["archive"]["bytes"] // part_size(tree))
    if n != len(calls):
        print(f"(for this tree the archive would go in {n} calls: `plan --resplit` re-splits it)")
    return 0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    b = sub.add_parser("build", help="download, check, pack and split the bundle; print the transfer plan")
    b.add_argument("--cache", type=Path, default=CACHE)
    b.add_argument("--preset", default="9e", help="xz preset (9e: smallest; 6: faster)")
    b.add_argument("--dict-mib", type=int, default=384, help="LZMA2 dictionary (0: the preset's; 384 spans warp.so)")
    b.add_argument("--without", nargs="*", default=[], help="plan as if these folders did not travel")
    c = sub.add_parser("check", help="check the wheels in DIR against the node's package list")
    c.add_argument("dir", type=Path, nargs="?", default=CACHE / "wheels")
    p = sub.add_parser("plan", help="the transfer plan for the working tree as it is now")
    p.add_argument("--cache", type=Path, default=CACHE)
    p.add_argument("--without", nargs="*", default=[])
    p.add_argument("--resplit", action="store_true", help="re-split the cached archive for the tree as it is")
    k = sub.add_parser("clips", help="copy the clip files to DIR (for CHARCTL_CLIP_DIR)")
    k.add_argument("dir", type=Path)
    a = ap.parse_args()
    if a.cmd == "build":
        sys.exit(build(a))
    if a.cmd == "check":
        res = check_dir(a.dir, default_roots(), load_node_packages())
        print("\n".join(res.lines()))
        sys.exit(0 if res.ok else 1)
    if a.cmd == "plan":
        sys.exit(cmd_plan(a))
    files = copy_clips(a.dir)
    print(f"{len(files)} files -> {a.dir} (export CHARCTL_CLIP_DIR={a.dir.resolve()})")


if __name__ == "__main__":
    main()
