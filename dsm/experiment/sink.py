"""The run's sink: where every finished case goes (metrics.csv, the run record, its images).

The runner, motion's frame loop and a Ray task's map group hand each case here as an evaluated
:class:`dsm.case.CaseResult` and its row; nothing else writes a case's files.
"""
from __future__ import annotations

import time
import weakref
from pathlib import Path

import numpy as np

from .. import pipeline
from ..case import CaseResult, MapContext
from ..core import record, signals
from ..report import figures, publish, tables as report, io as report_io
from ..report.sections import cascades as cascade_files, contact_images, soft as soft_report, virtual as virtual_files


class Sink:
    """Rows into metrics.csv and the record as cases finish; each case's images written at once
    (so a killed run keeps them), their time kept apart from measuring's."""

    def __init__(self, out: Path, run_record: record.RunRecord, images_mode: str, keep_images: bool = True,
                 files: bool = True):
        self.out = Path(out)
        self.record = run_record
        self.files = files                      # False: no image file at all (a caller that keeps the results only)
        self.images_mode = images_mode if files else "none"     # [report] images: "all", "errors" or "none"
        self.keep_images = keep_images
        self.images = {}                        # case id -> (H, W) class image (Results.rgb)
        self.images_s = self.images_cpu_s = 0.0  # drawing the case images: report work, not measuring
        self.csv = None
        self.cosines = (None, None)   # the shadow images' receiver set (weakly: never kept alive) and its cosines

    def open(self):
        """metrics.csv started (its header) and images/ made: before the first case."""
        self.out.mkdir(parents=True, exist_ok=True)
        (self.out / "images").mkdir(exist_ok=True)
        self.csv = report_io.CsvWriter(self.out / "metrics.csv")

    def add(self, row: dict, status: dict):
        """One finished case: its row into metrics.csv (refused unless it fits the schema,
        record.check_row) and the record, and its status, together: an interrupt waits for all three."""
        with signals.deferred():
            self.csv.write(row)
            self.record.rows.append(row)
            self.record.status.append(status)
            if row.get("hybrid_rule"):      # a rule's rays: run.json's rays beside the map's (dsm plan bounds them)
                self.record.add_rays({"hybrid": int(row["hybrid_rays"])})

    def still_case(self, ctx: MapContext, ident: dict, result: CaseResult):
        """A still case's per-cascade rows and curve, and its images (classes, shading, contact
        march, an area light's V, the cascade index or a virtual map's level)."""
        if result.cascades is not None:
            per, curve, faces = result.cascades
            self.record.cascade_rows += [{**ident, **r} for r in per]
            self.record.cascade_curves.append((ident, curve))
        if result.cascades is not None and self.files and ctx.view.virtual:
            virtual_files.write_level_image(self.folder(ident) / f"{ident['case']}_level.png", ctx.setup.pixels,
                                            ctx.view.levels[faces], *ctx.image_size)
        elif result.cascades is not None and self.files:
            folder = self.folder(ident)
            cascade_files.write_index_image(folder / f"{ident['case']}_cascade.png", ctx.setup.pixels, faces,
                                            *ctx.image_size)
        elif self.files and ctx.view.virtual and ctx.receivers.get(ident["format"]) is not None:
            # a spot or point light's virtual map (no per-cascade rows): each receiver's level by its face
            faces = np.asarray(ctx.receivers[ident["format"]].face.numpy(), int)
            virtual_files.write_level_image(self.folder(ident) / f"{ident['case']}_level.png", ctx.setup.pixels,
                                            ctx.view.level_of_face(faces), *ctx.image_size)
        self._images(ctx, ident, result)

    def folder(self, ident: dict) -> Path:
        """The case's image folder (images/<scene>_<light>/), made."""
        folder = self.out / "images" / figures.image_folder(ident)
        folder.mkdir(parents=True, exist_ok=True)
        return folder

    def _images(self, ctx: MapContext, ident: dict, result: CaseResult):
        # report work, timed apart; its CPU is this thread's (the images are drawn here,
        # single-threaded), so Dr.Jit's workers winding down the case's kernels stay measuring's
        t_img, c_img = time.perf_counter(), time.thread_time()
        setup, case_id, v = ctx.setup, ident["case"], result.v
        shade = None
        if self.images_mode == "all":
            positional = pipeline.is_positional(setup.light)
            shade = report.shade(result.classes.shape, ctx.gbuffer, setup, v, positional, self._cosines(setup))
        item = publish.image_item(ident, result.classes, shade, self.images_mode)
        if item is not None:        # written now (Pillow, ~1 ms, between timings): a killed run keeps them
            figures.write_images(self.out, [item])
        if result.occluded is not None and self.images_mode != "none":         # what the contact march did
            contact_images.write_image(self.folder(ident) / f"{case_id}_contact.png", setup.pixels,
                                       contact_images.classes(v, setup.v_star, result.occluded), *ctx.image_size)
        if setup.ref is not None and self.images_mode != "none":    # area light: V, V*, |V - V*|
            soft_report.write_images(self.out, [soft_report.image_item(ident, *ctx.image_size, setup.pixels,
                                                                       v, setup.v_frac)])
        self.images_s += time.perf_counter() - t_img
        self.images_cpu_s += time.thread_time() - c_img
        if self.keep_images:
            self.images[case_id] = result.classes

    def _cosines(self, setup) -> np.ndarray | None:
        """The receivers' cosines to the light for the shadow images, once per receiver set (every
        case of a map shares its set)."""
        if setup.n is None:
            return None
        held = self.cosines[0]() if self.cosines[0] is not None else None
        if held is not setup:
            self.cosines = (weakref.ref(setup), report.receiver_cosines(setup, pipeline.is_positional(setup.light)))
        return self.cosines[1]
