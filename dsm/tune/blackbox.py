"""Black-box search with Optuna, beside the gradient tuner at an equal number of exact evaluations.

TPE (Bergstra et al., "Algorithms for Hyper-Parameter Optimization", NeurIPS 2011) minimises the exact
training objective itself, not the relaxation the AD tuner descends, over the AD tuner's own search
box; NSGA-II (Deb et al., "A fast and elitist multiobjective genetic algorithm", IEEE TEC 2002) the two
objectives acne and peter-panning per receiver, whose weighted sum at lambda is the scalar objective.
One trial is one exact evaluation (evaluate.hard_counts over the training receivers).

A study lives in a journal file in the run folder (no database server) and resumes after an
interrupt: each trial's sampler is seeded from the study's seed and the number of trials completed
before it, so a resumed study draws the same trials as one never stopped (a trial cut short is marked
failed, and neither sampler reads failed trials).
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from ..core.types import ConfigError
from .evaluate import hard_counts, sync_clock, tallying, with_values

EXTRA = "pip install 'dsm[tune]'"     # the optional extra that brings Optuna (pyproject.toml)
JOURNAL = "optuna.journal"            # the studies' file in the tune's folder


def require_optuna(source: str):
    """Optuna's module, or a ConfigError naming the extra to install (checked before any work)."""
    try:
        import optuna
    except ImportError:
        raise ConfigError(source, "tune.search", f"\"optuna\" needs Optuna, an optional extra: {EXTRA}",
                          ("ad", "optuna")) from None
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    return optuna


def trial_seed(seed: int, completed: int) -> int:
    """The sampler's seed for the trial after ``completed`` finished ones (a 32-bit word of SeedSequence)."""
    return int(np.random.SeedSequence([seed, completed]).generate_state(1)[0])


def storage(out: Path | None):
    """The studies' storage: a journal file in ``out`` (in memory without one)."""
    optuna = require_optuna("dsm.tune")
    if out is None:
        return optuna.storages.InMemoryStorage()
    from optuna.storages.journal import JournalFileBackend
    return optuna.storages.JournalStorage(JournalFileBackend(str(Path(out) / JOURNAL)))


def journal_problem(out: Path) -> str | None:
    """Why ``--resume`` cannot go on with the studies' journal in ``out`` (None if it can, or there is
    none). An append a kill cut short (a last line without its newline, which Optuna skips) is cut off
    first: the resume's next append would join it into a line Optuna cannot read."""
    path = Path(out) / JOURNAL
    if not path.is_file():
        return None
    raw = path.read_bytes()
    whole = raw[: raw.rfind(b"\n") + 1]
    for n, line in enumerate(whole.splitlines(), 1):
        try:
            ok = isinstance(json.loads(line), dict)
        except ValueError:
            ok = False
        if not ok:
            return (f"--resume: {path} line {n} is not a record of Optuna's journal (a damaged file); "
                    "--force starts the tune again")
    if len(whole) < len(raw):
        with open(path, "r+b") as fh:
            fh.truncate(len(whole))
    return None


def _open_study(store, name: str, objectives: int):
    """The study ``name`` in ``store``, created or loaded; trials an interrupt cut short marked failed."""
    optuna = require_optuna("dsm.tune")
    directions = ["minimize"] * objectives
    study = optuna.create_study(study_name=name, storage=store, directions=directions, load_if_exists=True)
    for t in study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.RUNNING,)):
        study.tell(t.number, state=optuna.trial.TrialState.FAIL)
    return study


def _sampler(objectives: int, seed: int, population: int):
    optuna = require_optuna("dsm.tune")
    if objectives == 1:
        return optuna.samplers.TPESampler(seed=seed)
    return optuna.samplers.NSGAIISampler(seed=seed, population_size=population)


def population_size(trials: int) -> int:
    """NSGA-II's population at a budget of ``trials``: a fifth of it (five generations), 4 to 50 (Optuna's default)."""
    return int(min(50, max(4, trials // 5)))


def study(tc, spec, box, train, groups, trials: int, store, name: str, objectives: int = 1, on_trial=None) -> dict:
    """Run (or resume) study ``name`` until ``trials`` trials have completed: TPE on the exact objective
    (``objectives`` 1) or NSGA-II on (acne, peter-panning) per receiver (2) over ``box``, the first trial at
    the scheme's start clipped into the box (the AD tuner's first evaluation too). Returns every completed
    trial's values and objectives, the evaluations this call made and its wall and CPU time.
    ``on_trial(n)``, called after the n-th completed trial, is where a test interrupts."""
    optuna = require_optuna(tc.config.source)
    dist = {p.name: optuna.distributions.FloatDistribution(p.lo, p.hi) for p in box}
    st = _open_study(store, name, objectives)
    waiting = (optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.WAITING)
    if not st.get_trials(deepcopy=False, states=waiting):     # (a start cut short is failed: queued again)
        st.enqueue_trial({p.name: p.start for p in box})
    complete = lambda: st.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,))
    wall0, cpu0 = sync_clock(), time.process_time()
    with tallying() as tally:
        while len(complete()) < trials:
            done = len(complete())
            st.sampler = _sampler(objectives, trial_seed(tc.spec.seed, done), population_size(trials))
            trial = st.ask(dist)
            c = hard_counts(with_values(spec, trial.params), train, groups)
            n = max(c["n_receivers"], 1)
            values = ((c["n_acne"] + tc.spec.lam * c["n_peterpan"]) / n if objectives == 1
                      else [c["n_acne"] / n, c["n_peterpan"] / n])
            st.tell(trial, values)
            if on_trial:
                on_trial(done + 1)
    wall_ms, cpu_ms = (sync_clock() - wall0) * 1e3, (time.process_time() - cpu0) * 1e3
    done = sorted(complete(), key=lambda t: t.number)[:trials]
    return {"trials": [{"number": t.number, "values": {p.name: t.params[p.name] for p in box},
                        "objectives": list(t.values)} for t in done],
            "evaluations": tally.as_dict(), "wall_ms": wall_ms, "cpu_ms": cpu_ms}


def best_trial(result: dict) -> dict:
    """The completed trial of least objective (the first such, by trial number: a tie goes to the earlier)."""
    return min(result["trials"], key=lambda t: (t["objectives"][0], t["number"]))


def pareto_front(result: dict) -> list:
    """The points no completed trial dominates in (acne, peter-panning) per receiver, by acne (the earliest trial at each)."""
    pts = [(t["objectives"][0], t["objectives"][1], t) for t in result["trials"]]
    front = [t for a, p, t in pts if not any(a2 <= a and p2 <= p and (a2 < a or p2 < p) for a2, p2, _ in pts)]
    first = {}                # one trial per point of the front: the earliest that reached it
    for t in sorted(front, key=lambda t: t["number"]):
        first.setdefault(tuple(t["objectives"]), t)
    return sorted(first.values(), key=lambda t: (t["objectives"][0], t["objectives"][1]))
