"""The run record: what a run measured, in one typed place.

:data:`COLUMNS` is the schema of a case's row, metrics.csv's columns in order, each with its
kind (text, int, float) and its group: ``core`` (every case), ``map`` (a case on one map: its
exclusions, the split of its errors, its build and lookup costs), ``cascade`` (a cascaded map),
``motion`` (a case over frames), ``area`` (an area light's soft-shadow metrics),
``precision`` (the map's float32 headroom: :mod:`dsm.maps.headroom`), ``prefilter`` (a run whose
``[map] kind`` is given: every case's map kind, its peter-panning split into contact and leak,
and a moment map's build time), ``virtual`` (a virtual shadow map's pages, memory, rays and levels:
:mod:`dsm.truth.virtual`) ``transition`` (a cascaded or virtual map's texels per pixel spread and errors near a cascade
or level transition: :mod:`dsm.truth.transition`), ``cost`` (what a case costs in counts: the bytes its
lookup reads, its page table, its map's rays, its taps per lookup: :mod:`dsm.case.cost`), ``contact`` (a case with ``[contact]``'s screen-space contact
shadows after its lookup, dsm.contact) and ``hybrid`` (a case whose receivers a rule sends to rays: the
rays and the error left after them, dsm.hybrid). A row holds
the core group and each other group whole or not at all; :func:`check_row` refuses a column the
schema does not name and a group cut short, so a metric can no longer vanish from metrics.csv.

:class:`RunRecord` is the state a run accumulates (rows, statuses, oracle rows and curves, maps,
scenes, rays, cascade rows and curves, motion frames, reference regions). The runner, dsm.experiment.motion
and each Ray task write into one; :meth:`RunRecord.merge` folds a task's record into the
driver's.
"""
from __future__ import annotations

from dataclasses import dataclass, field

TEXT, INT, FLOAT = "text", "int", "float"

# the leak split's columns (dsm.truth.metrics.leak_split) and an area light's (dsm.truth.metrics.soft)
LEAK_COLUMNS = ("n_peterpan_edge", "n_leak", "peterpan_edge_rate", "leak_rate")
SOFT_COLUMNS = ("n_umbra", "n_penumbra", "n_lit", "rmse", "mae_umbra", "mae_penumbra", "mae_lit", "rmse_umbra",
                "rmse_penumbra", "rmse_lit", "ref_half_width_mean", "ref_half_width_max", "ref_samples_mean")


@dataclass(frozen=True)
class Column:
    """One column of metrics.csv: its name, kind and group."""
    name: str
    kind: str
    group: str


def _cols(group: str, spec: str) -> list:
    """Columns of one group from ``name:kind`` words (kind t, i or f; n_* counts default to int)."""
    kinds = {"t": TEXT, "i": INT, "f": FLOAT}
    out = []
    for word in spec.split():
        name, _, k = word.partition(":")
        out.append(Column(name, kinds[k] if k else (INT if name.startswith("n_") else FLOAT), group))
    return out


# a virtual shadow map's (dsm.truth.virtual): pages, physical texels, rays, receivers and pages per level
VIRTUAL_COLUMNS = ["vsm_pages_tagged", "vsm_pages_built", "vsm_memory_texels", "vsm_rays", "vsm_level_histogram",
                   "vsm_level_pages"]
# a cascaded or virtual map's (dsm.truth.transition): texels per pixel's spread, errors near a transition
TRANSITION_COLUMNS = ["tpp_p10", "tpp_p90", "tpp_below_1", "n_transition", "transition_error_rate",
                      "off_transition_error_rate"]
# what a case costs in counts (dsm.case.cost): bytes its lookup reads, its page table, its map's rays, taps per lookup
COST_COLUMNS = ["map_bytes", "page_table_bytes", "map_rays", "taps"]
# a hybrid case's (dsm.hybrid): its rule, the rays it traced, their cost and the error left after them
HYBRID_COLUMNS = ("hybrid_rule:t hybrid_params:t hybrid_origin:t hybrid_rays:i ray_fraction hybrid_n_ray_wrong:i "
                  "hybrid_shortened:i hybrid_n_acne:i hybrid_n_peterpan:i hybrid_acne_rate hybrid_peterpan_rate "
                  "hybrid_error_rate hybrid_ms hybrid_compile_ms").split()
# a motion case's cache (dsm.experiment.cache): its policy, ghosts and missing shadows (mean and worst frame), texels re-cast
CACHE_COLUMNS = "cache ghost_rate missing_rate ghost_rate_worst missing_rate_worst recast_fraction".split()
CONTACT_COLUMNS = ("n_contact_false n_contact_recovered n_contact_missed contact_acne_rate contact_peterpan_rate "
                   "contact_error_rate contact_mean_abs_error contact_ms").split()

# metrics.csv's order (the order of the kit's releases, kept so old folders read the same)
_ORDER = (
    "case scene light view scheme preset params culling resolution total_texels filter format cascade_layout "
    "motion frames n_pixels n_excluded_nohit n_excluded_backfacing n_excluded_outside n_receivers n_gt_lit "
    "n_gt_shadowed n_acne n_acne_self n_acne_edge n_peterpan n_acne_resolution n_acne_bias n_peterpan_resolution "
    "n_peterpan_bias acne_rate peterpan_rate error_rate mean_abs_error peterpan_dist_median n_seam seam_error_rate "
    "off_seam_error_rate texel_size texels_per_pixel fit_ms n_plane_fallback n_backfacing backface_lit_rate "
    "flicker_rate flicker_ever flicker_magnitude flicker_within_rate flicker_change_rate maps_built build_ms "
    "build_first_ms build_compile_ms build_peak_mb lookup_ms lookup_compile_ms lookup_kernels_compiled "
    "reference_ms sweep_key sweep_value").split() + list(SOFT_COLUMNS) + ["f32_step", "texel_f32_steps", "map_kind",
                                                                         *LEAK_COLUMNS, "moments_ms"] + CONTACT_COLUMNS + [
    "lookup_shared", "build_shared"] + VIRTUAL_COLUMNS + TRANSITION_COLUMNS + COST_COLUMNS + [
    c.partition(":")[0] for c in HYBRID_COLUMNS] + CACHE_COLUMNS

_GROUPS = (
    _cols("core", "case:t scene:t light:t view:t scheme:t preset:t params:t culling:t resolution:i total_texels:i "
                  "filter:t format:t cascade_layout:t n_receivers n_gt_lit n_gt_shadowed n_acne n_acne_self "
                  "n_acne_edge n_peterpan acne_rate peterpan_rate error_rate mean_abs_error peterpan_dist_median "
                  "n_seam seam_error_rate off_seam_error_rate texel_size build_ms build_first_ms lookup_ms "
                  "reference_ms sweep_key:t sweep_value")
    + _cols("map", "n_pixels n_excluded_nohit n_excluded_backfacing n_excluded_outside n_acne_resolution n_acne_bias "
                   "n_peterpan_resolution n_peterpan_bias n_plane_fallback n_backfacing backface_lit_rate "
                   "build_compile_ms build_peak_mb lookup_compile_ms lookup_kernels_compiled:i lookup_shared:i build_shared:i")
    + _cols("cascade", "texels_per_pixel fit_ms")
    + _cols("motion", "motion:t frames:i flicker_rate flicker_ever flicker_magnitude flicker_within_rate "
                      "flicker_change_rate maps_built:i cache:t " + " ".join(CACHE_COLUMNS[1:]))
    + _cols("area", " ".join(SOFT_COLUMNS))
    + _cols("precision", "f32_step texel_f32_steps")
    + _cols("prefilter", "map_kind:t " + " ".join(LEAK_COLUMNS) + " moments_ms")
    + _cols("contact", " ".join(CONTACT_COLUMNS))
    + _cols("virtual", "vsm_pages_tagged:i vsm_pages_built:i vsm_memory_texels:i vsm_rays:i vsm_level_histogram:t "
                       "vsm_level_pages:t")
    + _cols("transition", " ".join(TRANSITION_COLUMNS))
    + _cols("cost", "map_bytes:i page_table_bytes:i map_rays:i taps")
    + _cols("hybrid", " ".join(HYBRID_COLUMNS)))

_BY_NAME = {c.name: c for c in _GROUPS}
COLUMNS = tuple(_BY_NAME[n] for n in _ORDER)
NAMES = [c.name for c in COLUMNS]
TEXT_COLUMNS = {c.name for c in COLUMNS if c.kind == TEXT}
INT_COLUMNS = {c.name for c in COLUMNS if c.kind == INT}
GROUPS = {g: {c.name for c in COLUMNS if c.group == g} for g in ("core", "map", "cascade", "motion", "area",
                                                                  "precision", "prefilter", "contact", "virtual",
                                                                  "transition", "cost", "hybrid")}


class SchemaError(ValueError):
    """A row that does not fit metrics.csv's schema (an unknown column, or a group cut short)."""


def check_row(row: dict) -> dict:
    """``row`` unchanged when it fits the schema; else SchemaError naming the columns."""
    unknown = sorted(set(row) - set(_BY_NAME))
    if unknown:
        raise SchemaError(f"case row with columns metrics.csv does not have: {', '.join(unknown)} "
                          "(add them to dsm.core.record.COLUMNS)")
    for group, names in GROUPS.items():
        have = names & set(row)
        if (have or group == "core") and have != names:
            raise SchemaError(f"case {row.get('case', '?')}: the {group} columns lack "
                              f"{', '.join(sorted(names - have))}")
    return row


@dataclass
class RunRecord:
    """Everything a run measured, as the runner, dsm.experiment.motion and Ray tasks accumulate it."""
    rows: list = field(default_factory=list)              # metrics.csv, one dict per case (check_row)
    status: list = field(default_factory=list)            # run.json status: cases, failures, notes
    oracle_rows: list = field(default_factory=list)       # oracle.csv
    curves: list = field(default_factory=list)            # (oracle row, world curve, texel curve) per map and format
    maps: list = field(default_factory=list)              # run.json maps
    scene_info: list = field(default_factory=list)        # run.json scenes: shapes and their closedness
    gbuffer_ms: dict = field(default_factory=dict)        # per scene
    rays: dict = field(default_factory=lambda: {"gbuffer": 0, "reference": 0, "map_texel": 0, "map_continue": 0})
    quantized: int = 0                                     # stored-format copies made
    cascade_rows: list = field(default_factory=list)      # cascades.csv
    cascade_curves: list = field(default_factory=list)    # (case meta, [(distance, error, texels/pixel)]) per case
    motion_frames: list = field(default_factory=list)     # frames.csv
    motion_gifs: list = field(default_factory=list)       # what each motion case's GIF needs (drawn in the report's time)
    reference_regions: list = field(default_factory=list)  # area lights: the reference's receivers and rays by region

    def add_rays(self, rays: dict):
        """Count ``rays`` (by kind) into the run's totals."""
        for k, v in rays.items():
            self.rays[k] = self.rays.get(k, 0) + v

    def merge(self, task: "RunRecord", node: str, worker: int, seen: set, gbuffer_once, reference_once):
        """Fold a Ray task's record in (its rows and cases tagged with ``node`` and ``worker``).
        ``seen``: the driver's set of notes and stages already counted; a scene's notes, its
        G-buffer rays (``gbuffer_once``: the scene) and a light's reference rays
        (``reference_once``: (scene, light)) are counted once over all tasks."""
        self.rows += task.rows
        for s in task.status:
            if s["what"].startswith("case "):
                self.status.append({**s, "node": node, "worker": worker})
                continue
            key = (s["what"], s["status"], s.get("error"))      # each task loads the scene: its notes once
            if key not in seen:
                seen.add(key)
                self.status.append(s)
        self.oracle_rows += task.oracle_rows
        self.curves += task.curves
        self.cascade_rows += task.cascade_rows
        self.cascade_curves += task.cascade_curves
        self.motion_frames += task.motion_frames
        self.motion_gifs += task.motion_gifs
        self.maps += [{**x, "node": node} for x in task.maps]
        self.scene_info += [i for i in task.scene_info if all(x["scene"] != i["scene"] for x in self.scene_info)]
        for k, v in task.gbuffer_ms.items():
            self.gbuffer_ms.setdefault(k, v)
        self.quantized += task.quantized
        self.reference_regions += [r for r in task.reference_regions if r not in self.reference_regions]
        first_scene, first_light = ("gbuffer", gbuffer_once) not in seen, ("reference", reference_once) not in seen
        seen |= {("gbuffer", gbuffer_once), ("reference", reference_once)}
        self.add_rays({k: v for k, v in task.rays.items()
                       if not (k == "gbuffer" and not first_scene) and not (k == "reference" and not first_light)})
