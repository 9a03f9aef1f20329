"""The documentation's generated pages, from the code itself: the config reference (dsm.config.keys and
the parameter dataclasses), the CLI reference (dsm's argparse parsers), the schemes and presets
(dsm.schemes' registries, what ``dsm schemes`` prints), the design split by topic (docs/design.md's
``## `` headings) and the notebooks as tutorials (their stored outputs). ``write_all(docs)`` writes
them under ``docs/_generated/`` (git-ignored); nothing here renders with Mitsuba."""
from __future__ import annotations

import dataclasses
import os
import re
import shutil
from pathlib import Path

import scheme_pages                # docs/_ext: one page per scheme

GENERATED = "_generated"


def md_cell(value) -> str:
    """A value as one Markdown table cell (pipes escaped, tuples as comma lists)."""
    if isinstance(value, (tuple, list)):
        value = ", ".join(str(v) for v in value)
    return escape(str(value)).replace("|", "\\|").replace("\n", " ")


def escape(text: str) -> str:
    """Text whose '<' is shown, not read as an HTML tag (runs/<name>-<time>)."""
    return text.replace("<", "&lt;")


def key_table(keys) -> list:
    """Markdown lines of a table of config keys (dsm.config.keys.Key)."""
    lines = ["| key | type | unit | default | valid | source | meaning |", "|---|---|---|---|---|---|---|"]
    for k in keys:
        name = f"`{k.name}`" + (" (list sweeps)" if k.sweeps else "")
        lines.append("| " + " | ".join(md_cell(v) for v in (name, k.type, k.unit, k.default, k.valid, k.source,
                                                              k.doc)) + " |")
    return lines


def config_reference() -> str:
    """The config reference page: every table's keys, then the dataclass-read tables."""
    from dsm.config import keys
    from dsm.core.types import ContactSpec
    from dsm.scenes.params import BUILTINS
    from dsm import prefilter
    out = ["# Config reference", "",
           "Every key of an experiment config (TOML), generated from `dsm/config/keys.py` and the parameter "
           "dataclasses, which the reader is tested against: a key missing here is refused by `dsm run`. "
           "A list where a single value is expected sweeps (multiplies the cases) where the key says so. "
           "Lengths are a number (world units), `\"k texel\"` (texel widths at the receiver) or `\"k range\"` "
           "(a fraction of the view's depth range). For an annotated tour see [Experiment configs](../../config.md).",
           ""]
    for table in keys.TABLES:
        arr = table in ("scene", "light", "scheme", "motion") or table == "tune.camera"
        out += [f"## [{'[' if arr else ''}{table}{']' if arr else ''}]", ""] + key_table(keys.keys_of(table)) + [""]
        if table == "contact":
            out += ["The march's parameters (one value each):", ""] + key_table(keys.dataclass_keys(
                "contact", ContactSpec, keys.contact_bounds())) + [""]
        if table == "scene":
            out += _scene_params(keys, BUILTINS)
    out += ["## [map.&lt;kind&gt;]: pre-filtered maps", "",
            "Each kind's parameters (lists sweep), or `preset = \"...\"` (see [Schemes and presets](schemes.md)).", ""]
    for k in prefilter.REGISTRY:
        out += [f"### [map.{k.NAME}]", "", f"{k.SOURCE}. {_first_line(k.Params.__doc__)}", ""]
        out += key_table(keys.dataclass_keys(f"map.{k.NAME}", k.Params)) + [""]
    return "\n".join(out)


def _scene_params(keys, builtins) -> list:
    """The built-in scenes' own parameters (and the placement every scene takes)."""
    out = ["### Built-in scenes and their parameters", "",
           "Every built-in takes `scale`, `translate` and `precision`; a mesh or XML `file` takes `scale` and "
           "`translate`. Lists sweep.", ""]
    from dsm.scenes.params import FileParams
    for name, cls in [(f'builtin = "{n}"', c) for n, c in builtins.items()] + [('file = "..."', FileParams)]:
        out += [f"#### `{name}`", "", _first_line(cls.__doc__), ""]
        out += key_table(keys.dataclass_keys("scene", cls)) + [""]
    return out


def _first_line(doc) -> str:
    """A docstring's first paragraph on one line."""
    return escape(" ".join((doc or "").strip().split("\n\n")[0].split()))


def cli_reference() -> str:
    """The CLI reference page: every subcommand's help as argparse prints it."""
    os.environ["COLUMNS"] = "100"          # argparse wraps at the terminal's width: a fixed one, the same page
    from dsm import cli
    parser = cli.parser()
    out = ["# Command-line reference", "",
           "Generated from dsm's argparse parsers (`dsm/cli.py`, `dsm/benchmark/command.py`): what "
           "`dsm COMMAND --help` prints.", "", "```text", parser.format_help().rstrip(), "```", ""]
    for name, sub in subparsers(parser):
        out += [f"## dsm {name}", "", "```text", sub.format_help().rstrip(), "```", ""]
    return "\n".join(out)


def subparsers(parser) -> list:
    """(name, parser) of each subcommand, aliases once, in the parser's order."""
    seen, out = set(), []
    for action in parser._actions:          # argparse keeps its actions there; subcommands map names to parsers
        if isinstance(action.choices, dict):
            for name, sub in action.choices.items():
                if id(sub) not in seen:
                    seen.add(id(sub))
                    out.append((name, sub))
    return out


def schemes_reference() -> str:
    """The schemes and presets page: dsm.schemes' registry, its engine presets, contact and pre-filter presets."""
    from dsm import cli, schemes
    from dsm.contact import presets as contact_presets
    out = ["# Schemes and presets", "",
           "Generated from the registries (`dsm.schemes.ALL`, `dsm.schemes.presets.PRESETS`, `dsm.contact.presets`, "
           "`dsm.prefilter`): what `dsm schemes` prints. Give a scheme as `[[scheme]] name = \"...\"` with its "
           "parameters (lists sweep), a preset as `[[scheme]] preset = \"...\"`.", ""]
    for s in schemes.ALL:
        out += [f"## {s.NAME}", "", f"{_first_line(s.__doc__)}", "", f"Source: {s.SOURCE}. Needs: "
                f"{', '.join(sorted(s.NEEDS)) or 'the first layer only'}.", ""]
        out += param_table(s.Params) + [""]
    out += ["## Engine presets", ""] + _presets_table() + [""]
    out += ["## Contact-shadow presets", "", "```text", *contact_presets.text(), "```", ""]
    out += ["## Pre-filtered maps and their presets", "", "```text", *cli.prefilter_text(), "```", ""]
    return "\n".join(out)


def param_table(cls) -> list:
    """Markdown lines of a parameter dataclass's fields: name, default, valid, meaning."""
    if not dataclasses.fields(cls):
        return ["No parameters."]
    lines = ["| parameter | default (as TOML) | valid | meaning |", "|---|---|---|---|"]
    for f in dataclasses.fields(cls):
        md = f.metadata
        valid = md.get("choices") or " ".join(x for x in (f">= {md['min']:g}" if "min" in md else "",
                                                           f"<= {md['max']:g}" if "max" in md else "") if x)
        lines.append(f"| `{f.name}` | {md_cell(default_text(f.default))} | {md_cell(valid)} | {md_cell(md.get('doc', ''))} |")
    return lines


def default_text(value) -> str:
    """A parameter's default as TOML, a depth step as the reports name it (``"2^-24 range"``, which a
    config reads back exactly), any other value exactly as the reader takes it."""
    from dsm.config.keys import exact_text
    from dsm.core.labels import power_of_two
    from dsm.core.types import Length
    if isinstance(value, Length) and value.unit == "range" and power_of_two(value.value) is not None \
            and 2.0 ** power_of_two(value.value) == value.value:
        return f'"2^{power_of_two(value.value)} range"'
    return exact_text(value)


def _presets_table() -> list:
    """Markdown lines of the engine presets: values per light type and the files they were read in."""
    from dsm.core.types import describe_params
    from dsm.schemes import combined, presets
    lines = ["Each preset is a `combined` instance per light type; a term not verified in the engine's "
             "source is off.", "", "| preset | engine | " + " | ".join(presets.LIGHT_TYPES) + " | read in |",
             "|---|---|" + "---|" * len(presets.LIGHT_TYPES) + "---|"]
    for name in presets.names():
        p = presets.PRESETS[name]
        vals = [describe_params(combined.Params(**p.values[t])) for t in presets.LIGHT_TYPES]
        src = "; ".join(f"{f}: {what}" for f, what in p.sources)
        lines.append("| " + " | ".join(md_cell(v) for v in (f"`{name}`", p.engine, *vals, src)) + " |")
    lines += ["", "Units and what was left out, per preset:", ""]
    for name in presets.names():
        p = presets.PRESETS[name]
        lines.append(f"- `{name}`: {md_cell(p.mapping) or 'units as given'}"
                     + (f"; left out: {md_cell(p.left_out)}" if p.left_out else ""))
    return lines


LINK = re.compile(r"(\]\()([^)#\s][^)\s]*)(\))")


def design_pages(text: str) -> list:
    """docs/design.md split at its ``## `` headings: [(slug, markdown)], headings one level up, its
    relative links made relative to the generated folder (two levels below docs/)."""
    parts = re.split(r"(?m)^## ", text)
    intro, pages = parts[0], []
    for i, part in enumerate(parts[1:], 1):
        title, _, body = part.partition("\n")
        body = re.sub(r"(?m)^(#{3,6}) ", lambda m: m.group(1)[1:] + " ", body)
        body = LINK.sub(lambda m: m.group(1) + _rebase(m.group(2)) + m.group(3), body)
        slug = f"{i:02d}-" + re.sub(r"[^a-z0-9]+", "-", title.lower()).strip("-")[:48]
        pages.append((slug, f"# {title.strip()}\n{body}"))
    overview = intro.split("\n", 1)[1] if intro.startswith("# ") else intro
    return [("00-overview", "# Design: overview\n" + overview)] + pages


def _rebase(target: str) -> str:
    """A link target of docs/design.md as seen from docs/_generated/design/ (URLs and anchors kept)."""
    if re.match(r"^[a-z]+:", target) or target.startswith("/"):
        return target
    return "../../" + target


def write_all(docs: Path):
    """Write every generated page under ``docs/_generated/`` (replacing what was there)."""
    gen = docs / GENERATED
    shutil.rmtree(gen, ignore_errors=True)
    (gen / "reference").mkdir(parents=True)
    (gen / "reference" / "config.md").write_text(config_reference())
    (gen / "reference" / "cli.md").write_text(cli_reference())
    (gen / "reference" / "schemes.md").write_text(schemes_reference())
    (gen / "design").mkdir()
    for slug, text in design_pages((docs / "design.md").read_text()):
        (gen / "design" / f"{slug}.md").write_text(text)
    scheme_pages.write_pages(gen)
    (gen / "tutorials").mkdir()
    for nb in sorted((docs.parent / "notebooks").glob("*.ipynb")):
        shutil.copyfile(nb, gen / "tutorials" / nb.name)
