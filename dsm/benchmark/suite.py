"""The frozen suites: their definitions (suite_<n>.toml in the package), their hashes, and the run configs they make.

One config per (scene, unit, offset): the scene at ``scale = factor * unit`` (factor: native units
to metres; unit: 100 for centimetres, 1 for metres, 0.001 for kilometres), at the origin or, from
dsm-bench-2 on, moved by an offset's ``translate`` at the suite's ``far_unit``, its three lights and
every contender. Spot and point positions are stated in metres about the scene's centre and handed to
the kit in the scene's native units (the kit multiplies a light's position by the scene's scale).

From dsm-bench-3 on a scene may name its own ``lights`` (a subset of the suite's) and its own ``spot``
and ``point`` (the Cornell box: inside the box), may stay off the far axis (``far = false``: an XML
scene takes no translate), and a case carries a second config, ``prefiltered``: the suite's
pre-filtered map kinds on the same scene and lights, without cascades (a kind refuses them) and
without [[scheme]] (which belongs to the depth map). Its tuned contenders (``[contenders.tuned.<name>]``:
a scheme's table with the values a tune froze) run as [[scheme]] tables among the others; their rows
are told from the same scheme at its defaults by their parameters' label (:func:`tuned_labels`). A case of
one of its ``[flicker]`` scenes at the flicker unit, at the origin, carries a third config, ``motion``:
the depth config with the suite's [[motion]] camera move.

From dsm-bench-4 on ``[prefiltered] presets`` adds each kind's engine presets (after its defaults) and
``[flicker] prefiltered = true`` gives such a case a fourth config, ``prefiltered_motion``: the
pre-filtered config with the same [[motion]]. An XML scene takes ``translate``: no scene is off the far axis.

From dsm-bench-5 on ``[virtual]`` gives a case whose scene runs the directional light a fifth config,
``virtual``: that light alone on the suite's virtual shadow map presets with its one scheme
(:func:`virtual_config`).

From dsm-bench-6 on ``[hybrid]`` gives every case a sixth config, ``hybrid``: the depth config with the suite's
one scheme and each ``[[hybrid.contender]]`` as a ``[[hybrid]]`` instance (:func:`hybrid_config`): a receiver the
rule sends to a ray gets the ray's answer (docs/hybrid.md).
"""
from __future__ import annotations

import hashlib
import tomllib
from dataclasses import dataclass
from pathlib import Path

from ..core.env import meshes_folder
from ..core.suggest import unknown

# every version, oldest first; the newest is what ``dsm benchmark`` runs unless told otherwise
SUITE_FILES = {"dsm-bench-1": Path(__file__).with_name("suite_1.toml"),
               "dsm-bench-2": Path(__file__).with_name("suite_2.toml"),
               "dsm-bench-3": Path(__file__).with_name("suite_3.toml"),
               "dsm-bench-4": Path(__file__).with_name("suite_4.toml"),
               "dsm-bench-5": Path(__file__).with_name("suite_5.toml"),
               "dsm-bench-6": Path(__file__).with_name("suite_6.toml")}
LATEST = list(SUITE_FILES)[-1]
SUITE_FILE = SUITE_FILES[LATEST]
ORIGIN = "0"              # the offset label of a case at the origin (every case of dsm-bench-1)
MESHES = meshes_folder()       # the suite's meshes: a checkout's data/meshes or a wheel's copy
SIZES = ("test", "default", "full")
# Calls a case's map builds, moment maps and lookups are timed over (dsm.core.timing): the first
# cold, the reported time the second's. A dsm run times 3 (the median of two warm calls); the
# benchmark's time columns are means over the many cases of a contender, where one warm call per case
# is enough. One call alone would read the builds' times alike (per-contender means within 8 %) but
# the lookups' at twice their warm time (docs/bench/benchmark-default/README.md).
TIMING_CALLS = 2
LIGHTS = ("directional", "spot", "point")


@dataclass(frozen=True)
class Case:
    """One run of the suite: a scene at one unit and offset, with its lights and contenders."""
    scene: str
    unit: str
    scale: float          # the config's ``scale``: native units to the unit's world units
    config: dict
    offset: str = ORIGIN  # the offset's label ("0", "1e4", ...)
    translate: tuple = (0.0, 0.0, 0.0)    # world units after the scale
    prefiltered: dict | None = None       # the pre-filtered kinds' config of the case (dsm-bench-3 on)
    motion: dict | None = None            # the flicker config of the case (dsm-bench-3 on, a few scenes)
    prefiltered_motion: dict | None = None  # the pre-filtered kinds' flicker config (dsm-bench-4 on)
    virtual: dict | None = None           # the virtual shadow maps' config (dsm-bench-5 on)
    hybrid: dict | None = None            # the hybrid rays' config (dsm-bench-6 on)


def suite_sha256(path: Path = SUITE_FILE) -> str:
    """The SHA-256 of the suite's definition file (its bytes): the suite's identity."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def load_suite(path: Path = SUITE_FILE) -> dict:
    """The suite's definition as a dict (the TOML)."""
    return tomllib.loads(Path(path).read_text())


def size_of(suite: dict, size: str) -> dict:
    """The pinned size ``size``: scenes, units, lights, contenders and resolutions (defaults: everything)."""
    if size not in SIZES:
        raise ValueError(unknown("suite size", size, SIZES))
    s = dict(suite["size"][size])
    s.setdefault("scenes", [sc["name"] for sc in suite["scene"]])
    s.setdefault("units", [u for u, _ in suite["suite"]["units"]])
    s.setdefault("lights", list(LIGHTS))
    s.setdefault("contenders", suite["contenders"]["presets"] + suite["contenders"]["schemes"]
                 + list(suite["contenders"].get("tuned", {})))
    s.setdefault("offsets", [label for label, _ in suite["suite"].get("offsets", [])])
    s.setdefault("prefiltered", suite.get("prefiltered", {}).get("kinds", []))
    s.setdefault("flicker", suite.get("flicker", {}).get("scenes", []))
    return s


def axes(suite: dict, s: dict, scene: dict | None = None) -> list:
    """The (unit, offset label, translate) of each run of a scene at size ``s``: every unit at the
    origin, then each far offset at the suite's ``far_unit`` (none for a scene with ``far = false``)."""
    translate = {label: tuple(float(c) for c in t) for label, t in suite["suite"].get("offsets", [])}
    out = [(u, ORIGIN, (0.0, 0.0, 0.0)) for u in s["units"]]
    if scene is not None and not scene.get("far", True):
        return out
    return out + [(suite["suite"]["far_unit"], o, translate[o]) for o in s["offsets"] if o != ORIGIN]


def contender_tables(suite: dict, names: list) -> list:
    """The [[scheme]] tables of the contenders ``names``: presets by name, tuned ones with their frozen
    values, kit schemes at their defaults."""
    presets, tuned = set(suite["contenders"]["presets"]), suite["contenders"].get("tuned", {})
    return [{"preset": n} if n in presets else dict(tuned[n]) if n in tuned else {"name": n} for n in names]


def tuned_labels(suite: dict) -> dict:
    """(scheme name, parameters label) -> tuned contender name, the label as a run's ``params`` column
    writes it; refused where a tuned table's label is its scheme's default's (its rows would be the same)."""
    from ..config.read import parse_scheme
    from ..schemes import ALL, PRESETS
    out = {}
    for name, t in suite["contenders"].get("tuned", {}).items():
        spec, = parse_scheme(dict(t), "<suite>", f"contenders.tuned.{name}", ALL, PRESETS)
        default, = parse_scheme({"name": t["name"]}, "<suite>", "default", ALL, PRESETS)
        if spec.label == default.label:
            raise ValueError(f"contenders.tuned.{name}: its values are {t['name']}'s defaults")
        out[(t["name"], spec.label)] = name
    return out


def scene_table(scene: dict, scale: float, translate=(0.0, 0.0, 0.0)) -> dict:
    """The [[scene]] table of one suite scene at ``scale``, moved by ``translate`` (given only when not the origin)."""
    where = {"translate": list(translate)} if any(translate) else {}
    if "file" in scene:      # closed: the mesh's, where the suite states it (an XML scene's shapes are detected)
        closed = {"closed": {"mesh": scene["closed"]}} if "closed" in scene else {}
        return {"file": str(MESHES / scene["file"]), "scale": scale, **where, **closed}
    skip = ("name", "factor", "builtin")
    return {"builtin": scene["builtin"], "scale": scale, **where, **{k: v for k, v in scene.items() if k not in skip}}


def scene_lights(scene: dict, lights: list) -> list:
    """The lights of ``lights`` a scene runs under: those its own ``lights`` names (default: all), in order."""
    return [kind for kind in lights if kind in scene.get("lights", lights)]


def light_tables(suite: dict, scene: dict, lights: list) -> list:
    """The [[light]] tables of one scene, positions in its native units (metres / factor)."""
    out = []
    for kind in scene_lights(scene, lights):
        if kind == "directional":
            out.append({"type": "scene"})
            continue
        if "file" in scene:           # metres about the mesh's centre (the scene's own light, else the suite's)
            t = dict(scene.get(kind, suite["lights"]["mesh"][kind]))
            c = scene["centre"]
            t["position"] = [(ci + pi) / scene["factor"] for ci, pi in zip(c, t["position"])]
            if kind == "spot":
                t["target"] = [ci / scene["factor"] for ci in c]
        else:
            t = dict(suite["lights"]["builtin"][kind])
        out.append({"type": kind, **t})
    return out


def prefiltered_config(suite: dict, cfg: dict, kinds: list) -> dict | None:
    """The pre-filtered kinds' config of a case's depth config ``cfg``: its scene, camera and lights,
    the map without cascades, ``kinds`` at their defaults with the suite's blur; None without kinds."""
    if not kinds:
        return None
    mp = {k: v for k, v in cfg["map"].items() if k != "cascades"}
    mp.update({"kind": list(kinds), "blur": list(suite["prefiltered"]["blur"])})
    presets = suite["prefiltered"].get("presets", {})
    mp.update({k: {"preset": ["default", *presets[k]]} for k in kinds if presets.get(k)})
    name = cfg["experiment"]["name"] + "-prefiltered"
    return {**{k: v for k, v in cfg.items() if k != "scheme"}, "experiment": {"name": name}, "map": mp}


def virtual_config(suite: dict, cfg: dict, scene: dict, lights: list) -> dict | None:
    """The virtual shadow maps' config of a case's depth config ``cfg``: its scene and camera, the
    directional light alone, the suite's presets (levels in physical size: ``unit_cm`` 100 x the scene's
    factor) and its one scheme; None without ``[virtual]`` or where the scene does not run that light."""
    v = suite.get("virtual")
    if not v or "directional" not in scene_lights(scene, lights):
        return None
    mp = {"virtual": {"preset": list(v["presets"]), "unit_cm": 100.0 * scene["factor"]}}
    return {**cfg, "experiment": {"name": cfg["experiment"]["name"] + "-virtual"},
            "light": [t for t in cfg["light"] if t["type"] == "scene"], "map": mp, "scheme": [dict(v["scheme"])]}


def hybrid_tables(suite: dict) -> list:
    """The [[hybrid]] tables of the suite's hybrid contenders (each its rule and parameters, no name), in order."""
    return [{k: v for k, v in c.items() if k != "name"} for c in suite.get("hybrid", {}).get("contender", [])]


def hybrid_config(suite: dict, cfg: dict) -> dict | None:
    """The hybrid rays' config of a case's depth config ``cfg``: the same scene, camera, lights and map with the
    suite's one scheme and its contenders as [[hybrid]] instances; None without ``[hybrid]``."""
    tables = hybrid_tables(suite)
    if not tables:
        return None
    return {**cfg, "experiment": {"name": cfg["experiment"]["name"] + "-hybrid"},
            "scheme": [dict(suite["hybrid"]["scheme"])], "hybrid": tables}


def hybrid_labels(suite: dict) -> dict:
    """(rule, parameters label) -> hybrid contender name, the label as a run's ``hybrid_params`` column writes
    it; refused where two contenders share their rule and label (their rows would be the same)."""
    from ..core.types import HybridSpec
    from ..hybrid import get as rule_of
    out = {}
    for c in suite.get("hybrid", {}).get("contender", []):
        params = {k: v for k, v in c.items() if k not in ("name", "rule", "origin")}
        spec = HybridSpec(c["rule"], rule_of(c["rule"]).Params(**params), c.get("origin", "spawn"))
        if (spec.rule, spec.label) in out:
            twin = out[(spec.rule, spec.label)]
            raise ValueError(f"hybrid.contender {c['name']!r}: the same rule and values as {twin!r}")
        out[(spec.rule, spec.label)] = c["name"]
    return out


def motion_config(suite: dict, cfg: dict) -> dict:
    """The flicker config of a case's depth config ``cfg``: the same with the suite's [[motion]]."""
    name = cfg["experiment"]["name"] + "-flicker"
    return {**cfg, "experiment": {"name": name}, "motion": [dict(suite["flicker"]["motion"])]}


def cases(suite: dict, size: str) -> list:
    """Every (scene, unit, offset) Case of the suite at ``size``, each with its dsm.run config dict."""
    s = size_of(suite, size)
    units = dict((u, f) for u, f in suite["suite"]["units"])
    by_name = {sc["name"]: sc for sc in suite["scene"]}
    out = []
    for name in s["scenes"]:
        scene = by_name[name]
        for unit, offset, translate in axes(suite, s, scene):
            scale = scene["factor"] * units[unit]
            mp = {"resolution": s["map"], "view": "cube"}      # cube: the point light's view
            if "directional" in scene_lights(scene, s["lights"]):
                mp["cascades"] = suite["lights"]["directional"]["cascades"]
            where = "" if offset == ORIGIN else f"-at-{offset}"
            cfg = {"experiment": {"name": f"{suite['suite']['name']}-{name}-{unit}{where}"},
                   "camera": {"resolution": [s["camera"], s["camera"]]},
                   "scene": [scene_table(scene, scale, translate)],
                   "light": light_tables(suite, scene, s["lights"]),
                   "map": mp, "scheme": contender_tables(suite, s["contenders"]),
                   "timing": {"repeats": TIMING_CALLS}}
            flicker = name in s["flicker"] and unit == suite["flicker"]["unit"] and offset == ORIGIN
            pre = prefiltered_config(suite, cfg, s["prefiltered"])
            pre_flicker = flicker and pre is not None and suite["flicker"].get("prefiltered", False)
            out.append(Case(name, unit, scale, cfg, offset, translate, pre, motion_config(suite, cfg) if flicker else None,
                            motion_config(suite, pre) if pre_flicker else None,
                            virtual_config(suite, cfg, scene, s["lights"]), hybrid_config(suite, cfg)))
    return out


def contender_count(case: Case) -> int:
    """How many contenders a case's configs run (the oracle aside): its [[scheme]] tables, each pre-filtered kind
    at its defaults and engine presets under each blur, the virtual maps' presets and the hybrid contenders."""
    n = len(case.config["scheme"])
    if case.prefiltered is not None:
        mp = case.prefiltered["map"]
        n += sum(len(mp.get(k, {}).get("preset", ["default"])) for k in mp["kind"]) * len(mp["blur"])
    if case.virtual is not None:
        n += len(case.virtual["map"]["virtual"]["preset"])
    if case.hybrid is not None:
        n += len(case.hybrid["hybrid"])
    return n


def size_summary(suite: dict, size: str) -> str:
    """One line on the suite at ``size``, counted from its cases: cases (scenes x units + far offsets), lights,
    contenders (the most a case runs), camera and map resolutions."""
    s, runs = size_of(suite, size), cases(suite, size)
    far = [o for o in s["offsets"] if o != ORIGIN]
    axes_words = f"{len(s['units'])} units" + (f" + {len(far)} far offsets" if far else "")
    lights = f"{len(s['lights'])} light{'s' if len(s['lights']) > 1 else ''} ({', '.join(s['lights'])})"
    return (f"{len(runs)} cases ({len(s['scenes'])} scenes x ({axes_words})), {lights}, "
            f"{max(map(contender_count, runs))} contenders, camera {s['camera']}^2, map {s['map']}^2")
