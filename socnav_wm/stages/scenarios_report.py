"""Stage ``scenarios_report``: the per-preset table of every non-learning method, the
``oracle-mpc`` − ``cv-mpc`` gaps and the field's published rows side by side
(:mod:`socnav_wm.evaluation.scenarios`)."""

from __future__ import annotations

from pathlib import Path

from socnav_wm.config import Params
from socnav_wm.evaluation.rendering import replace_marked_block
from socnav_wm.evaluation.scenarios import scenario_table
from socnav_wm.io import outputs_together, write_json_atomic
from socnav_wm.stages.common import open_stage


def presets_in(folder: Path) -> list[str]:
    """The preset names: the overlays ``folder/*.yaml``, sorted."""
    return sorted(path.stem for path in folder.glob("*.yaml"))


def run(
    params: Params,
    *,
    presets_dir: Path,
    metrics_dir: Path,
    episodes_dir: Path,
    out: Path,
    summary: Path,
    documents: tuple[Path, ...],
    tracking: bool = True,
) -> str:
    """The table of what ``metrics_dir`` holds for the presets of ``presets_dir``, written to
    ``out`` (markdown), ``summary`` (JSON) and the ``scenarios`` block of ``documents``."""
    presets = presets_in(presets_dir)
    if not presets:
        raise ValueError(f"{presets_dir}: no scenario preset (*.yaml)")
    table = scenario_table(metrics_dir, episodes_dir, presets)
    body = table.markdown()
    texts = {
        path: replace_marked_block(path.read_text(encoding="utf-8"), "scenarios", body)
        for path in documents
    }
    targets = (out, summary, *texts)
    with open_stage("scenarios_report", "scenarios-report", params, tracking=tracking) as run:
        with outputs_together(*targets) as temporary:
            temporary[0].write_text("# Scenario presets: non-learning methods\n\n" + body, "utf-8")
            write_json_atomic(temporary[1], table.to_dict())
            for path, text in zip(temporary[2:], texts.values(), strict=True):
                path.write_text(text, encoding="utf-8")
        run.log_artifact(out)
    rooms = [preset for preset, gap in table.gaps.items() if gap["room"]]
    missing = f"; missing: {', '.join(table.missing)}" if table.missing else ""
    return (
        f"wrote {out}: {len(table.summaries)} presets; oracle-mpc − cv-mpc ≥ 3 points in "
        f"{', '.join(rooms) or 'none'}{missing}"
    )
