"""dsm grad's configs for tests: the kit's tables ([[scene]], [[light]], [map], [[scheme]]) and [gradient]
built from short keyword arguments named as GradSpec's fields (a test states a scene in one line)."""
import math

import pytest

# GradSpec field -> (the kit's table, its key there)
SCENE = {"occluder_size": "size", "occluder_height": "height", "box_height": "box_height", "mesh": "mesh"}
BUILTIN = {"plate": "occluder_plate", "box": "occluder_box", "mesh": "occluder_mesh"}
LIGHT = {"point": "spot", "directional": "directional", "area": "area"}
DEPTH_FILTERS = ("nearest", "pcf_bilinear", "pcss")


def config(scene="plate", light="point", light_height=2.0, light_angle=20.0, light_size=None,
           map_resolution=128, techniques=None, blur=None, antialias=None, bias=0.02, **gradient) -> dict:
    """A config dict dsm grad reads: GradSpec's scene, light and map fields as the kit's tables, the rest
    (the [gradient] table's own keys) as given; ``techniques`` a list of depth filters and moment kinds."""
    sc = {"builtin": BUILTIN[scene]}
    for field, key in SCENE.items():
        if field in gradient:
            sc[key] = gradient.pop(field)
    lt = {"type": LIGHT[light]}
    if light == "directional":
        a = math.radians(light_angle)
        lt["direction"] = [math.sin(a), 0.0, -math.cos(a)]
    else:
        lt.update(position=[0.0, 0.0, light_height], direction=[0.0, 0.0, -1.0])
    if light == "area":
        lt.update(shape="rectangle", size=0.1 if light_size is None else light_size)
    elif light_size is not None:
        gradient["pcss_light_size"] = light_size
    mp = {"resolution": map_resolution}
    names = list(techniques) if techniques is not None else list(DEPTH_FILTERS) + ["vsm", "esm", "evsm", "msm"]
    filters = [n for n in names if n in DEPTH_FILTERS]
    mp["kind"] = (["depth"] if filters else []) + [n for n in names if n not in DEPTH_FILTERS]
    if filters:
        mp["filter"] = filters
    if any(n not in DEPTH_FILTERS for n in names):
        mp["blur"] = [1, 3, 5] if blur is None else blur
    mp["antialias"] = [False, True] if antialias is None else antialias
    out = {"gradient": gradient, "scene": [sc], "light": [lt], "map": mp}
    if filters:
        out["scheme"] = [{"name": "constant", "bias": bias}]
    return out


def value_text(v) -> str:
    """One TOML value: a boolean, number, string, list or inline table."""
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(value_text(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {value_text(x)}" for k, x in v.items()) + "}"
    return repr(v)


def toml(cfg: dict) -> str:
    """A config dict (``config``'s) as TOML text: tables, then arrays of tables."""
    out = []
    for name, body in cfg.items():
        for table in (body if isinstance(body, list) else [body]):
            out.append(f"[[{name}]]" if isinstance(body, list) else f"[{name}]")
            out += [f"{k} = {value_text(v)}" for k, v in table.items()]
    return "\n".join(out) + "\n"


def toml_config(**kw) -> str:
    """``config(**kw)`` as TOML text."""
    return toml(config(**kw))


# dsm grad --compare --inverse on a tiny plate: the report's tables and words (test_grad_report) and the
# report in Chromium (test_browser) read the same run
TINY = toml_config(map_resolution=24, image_resolution=16, techniques=["pcf_bilinear", "vsm"], blur=[3],
                   antialias=[False, True], params=["occluder_z", "light_height"], reference_samples=8,
                   projective_spp=2, projective_integrators=["direct_projective"], projective_seeds=1,
                   inverse_starts=[-0.05, 0.05], inverse_iterations=3)


@pytest.fixture(scope="session")
def tiny_grad_run(tmp_path_factory):
    """The out folder of ``dsm grad --compare --inverse`` on TINY, run once per session and once across
    pytest-xdist's workers (as the kit's dsm_results runs a config); tests only read it."""
    from dsm.cli import main
    from dsm.pytest_plugin import run_once_shared, shared_folder

    def make():
        d = tmp_path_factory.mktemp("gradtiny")
        (d / "g.toml").write_text(TINY)
        assert main(["grad", str(d / "g.toml"), "--compare", "--inverse", "--out", str(d / "out")]) == 0
        return d / "out"
    shared = shared_folder(tmp_path_factory)
    return make() if shared is None else run_once_shared(shared, ("dsm grad", TINY), make)
