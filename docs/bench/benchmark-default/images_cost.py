"""What a benchmark run's case images and contender pages cost: the work the run adds for them,
redone on a finished run's folder and timed (CPU and wall seconds of this process).

    PYTHONPATH=. python docs/bench/benchmark-default/images_cost.py RUN_DIR OUT.json

For every case of RUN_DIR/results.json its records' stored class images and FLIP maps are read back
(not timed) and its sheets written again by ``case_images.keep`` into a temporary folder (timed: the
quantisation, the stacking, the PNG encoding and the atomic writes the run makes per case), then
the contender pages are written again into RUN_DIR (timed). It also states the folders' sizes: the files' bytes and the disk blocks
they take (``du``'s count).
"""
import json
import os
import sys
import tempfile
import time
from pathlib import Path

from dsm.benchmark import case_images, contenders


def folder_size(path: Path) -> dict:
    """Files, their bytes, and the bytes of the disk blocks they take."""
    files = [p for p in path.rglob("*") if p.is_file()]
    return {"files": len(files), "bytes": sum(p.stat().st_size for p in files),
            "disk_bytes": sum(p.stat().st_blocks * 512 for p in files)}


def main(run: Path, out: Path):
    doc = json.loads((run / "results.json").read_text())
    groups = {}
    for i, r in enumerate(doc["cases"]):
        if r["contender"] != "oracle":
            groups.setdefault(case_images.sheets(r)[0], []).append(i)
    stored = [([doc["cases"][i] for i in idx],
               [(case_images.read_class(run, doc["cases"], i), case_images.read_flip(run, doc["cases"], i))
                for i in idx]) for idx in groups.values()]
    with tempfile.TemporaryDirectory() as tmp:
        t, c = time.perf_counter(), time.process_time()
        for recs, images in stored:
            case_images.keep(Path(tmp), recs, images)
        keep = {"wall_s": time.perf_counter() - t, "cpu_s": time.process_time() - c, "cases": len(stored),
                "records": sum(len(r) for r, _ in stored)}
        t, c = time.perf_counter(), time.process_time()
        pages = contenders.write_pages(doc, run)
        write = {"wall_s": time.perf_counter() - t, "cpu_s": time.process_time() - c, "pages": len(pages)}
    result = {"run": str(run), "case_images_keep": keep, "contender_pages": write,
              "case_images": folder_size(run / case_images.FOLDER),
              "contenders": folder_size(run / contenders.FOLDER), "cpu": os.cpu_count()}
    out.write_text(json.dumps(result, indent=1))
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
