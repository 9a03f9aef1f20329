"""What a run derived from its scene file (``dsm run SCENE.xml``): the run folder's derivation.json
(written by dsm.config.derived_files before any case) read back for the report's first screen and
table.md, a line per choice before the answer. A run of a config file has none: nothing is shown."""
from __future__ import annotations

import json
from pathlib import Path

DERIVATION_JSON = "derivation.json"     # dsm.config.derived_files writes it under this name


def read(out: Path, notes: list | None = None) -> dict | None:
    """The run's derivation record, or None where the run was not derived (or the file is unreadable: a note)."""
    path = Path(out) / DERIVATION_JSON
    if not path.is_file():
        return None
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
        return {"scene": str(d["measured"]["scene"]), "name": Path(str(d["measured"]["scene"])).name,
                "choices": [{k: str(c[k]) for k in ("rule", "choice", "reason")} for c in d["choices"]]}
    except (OSError, ValueError, KeyError, TypeError) as e:
        if notes is not None:
            notes.append(f"{path}: unreadable ({type(e).__name__}), so the report does not say what was derived")
        return None


def md_lines(d: dict | None) -> list:
    """table.md's section on the derived choices (none for a run of a config file)."""
    if d is None:
        return []
    return ([f"## Derived from {d['name']}", "", f"Each choice of derived.toml (beside these results) for `{d['scene']}`, "
             "and why:", ""]
            + [f"- **{c['rule']}**: {c['choice']} ({c['reason']})" for c in d["choices"]] + [""])
