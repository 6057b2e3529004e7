"""The README's measured tables as recipes: the commands that made each one, and how its rows and columns map onto the
results those commands write. `bodyschema reproduce` runs them (run.py) and compares (readme_tables.py).

A step is a command line after `bodyschema`, as a user would type it, with placeholders: `{run}` (the reproduce run's
folder), `{workers}`, `{device}`, `{tracking}` (its MLflow store) and `{<step>}` (an earlier step's product: a
dataset's path, a model's `models:/<name>/<version>`, a benchmark's run folder). Steps are named once and shared:
a recipe that needs the levels' decoder names the step `decoder`, which runs once for every recipe that needs it.

A README cell holds one figure or several ("0.003 / 9.8 mm", "72 % (91 % within 1 px)"): each maps to a `Part`,
one value of a results CSV, found by its row's key. A README row names its CSV row by `Row.key`; a part whose `row`
holds "{}" puts that key in its place (the rubber hand's "d=5cm σ={}cm synchronous"), so one README row may read
several CSV rows, and a row may come from a step of its own (the reaching table's rows are separate runs).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Step:
    name: str
    command: str                     # after `bodyschema`; the README's own settings


@dataclass(frozen=True)
class Part:
    result: str                      # the results CSV's column
    row: str = "{}"                  # the CSV row's key; "{}" stands for the README row's `Row.key`
    scale: float = 1.0               # result × scale is in the README's unit (a fraction shown as % → 100)
    csv: str | None = None           # None: the table's CSV
    key: str | None = None           # None: the table's key column; "a,b": the values of columns a and b, joined by ","


@dataclass(frozen=True)
class Column:
    readme: str                      # the README table's header cell
    parts: tuple[Part, ...]          # the cell's figures in order


def column(readme: str, result: str, scale: float = 1.0, row: str = "{}") -> Column:
    """A column whose cells hold one figure."""
    return Column(readme, (Part(result, row, scale),))


@dataclass(frozen=True)
class Row:
    readme: str                      # the README row's first cell starts with this
    key: str = ""                    # its CSV row's key (what "{}" in a part's row stands for)
    step: str | None = None          # None: the table's step


@dataclass(frozen=True)
class Table:
    marker: str                      # the README holds `<!-- reproduce: <marker> -->` right above the table
    step: str                        # the step whose folder holds `csv` (a row may name its own)
    csv: str
    key: str                         # the CSV column naming a row
    rows: tuple[Row, ...]
    columns: tuple[Column, ...]
    spread: str | None = None        # the README column whose "± s" is the stated tolerance


@dataclass(frozen=True)
class Recipe:
    name: str
    about: str
    steps: tuple[Step, ...]
    table: Table


TRACKED = "--run-root {run}/runs --tracking-uri {tracking} --device {device}"
NAO_DATA = Step("nao_data", "datagen --robot nao_arm --n 18000 --workers {workers} --seed 0 "
                            "--out {run}/data/nao_arm.zarr")
DECODER = Step("decoder", "train pixel --data {nao_data} --epochs 60 --seed 0 " + TRACKED)
ENCODER = Step("encoder", "train encoder --data {nao_data} --epochs 40 --seed 0 " + TRACKED)
GPR_EE_PIXEL = Step("gpr_ee_pixel", "train gpr --data {nao_data} --modality ee_pixel --seed 0 " + TRACKED)


def _benchmark(name: str, command: str) -> Step:
    """A benchmark step writing under {run}/results/<name>; the README's runs use seed 0 (the default)."""
    return Step(name, f"{command} --out {{run}}/results/{name} --tracking-uri {{tracking}}")


LEVELS = Recipe(
    name="levels",
    about="the levels benchmark, 5 runs × 500 trials, lean pixel decoder + encoder (README: Estimation levels)",
    steps=(NAO_DATA, DECODER, ENCODER,
           _benchmark("levels", "evaluate levels --model {decoder} --encoder {encoder} --multistart 0 --runs 5 "
                                "--trials 500 --seed 0 --device {device} --workers {workers}")),
    table=Table(marker="levels", step="levels", csv="summary.csv", key="level",
                rows=(Row("floor", "floor"), Row("1 (", "1"), Row("1 +", "1+enc"), Row("2 (", "2"),
                      Row("2 +", "2+enc"), Row("3 (", "3"), Row("3 from", "3+enc")),
                columns=(column("mean", "joint_err_deg"), column("median", "joint_err_median_deg"),
                         column("every joint ≤ 2°", "all_joints_2deg", 100.0),
                         column("LElbowYaw", "joint_err_deg/LElbowYaw"),
                         column("evaluations per trial", "evaluations_per_trial")),
                spread="mean"),
)

RUBBER_HAND = Recipe(
    name="rubber-hand",
    about="rubber-hand drift, planar2, analytic models, 10 episodes per condition (README: Rubber-hand drift)",
    steps=(_benchmark("rubber_hand", "evaluate rubber-hand"),),
    table=Table(marker="rubber-hand", step="rubber_hand", csv="conditions.csv", key="condition",
                rows=tuple(Row(f"{sigma} cm", sigma) for sigma in ("0.5", "1", "2", "5")),
                columns=(*(column(f"d = {d} cm", "drift_cm", row=f"d={d}cm σ={{}}cm synchronous")
                           for d in (5, 10, 20, 30)),
                         column("async (every d)", "drift_cm", row="d=5cm σ={}cm asynchronous"))),
)

AGENCY_SENSES = (("pushed", "pushed [all senses]"), ("scene moved", "scene_moved [all senses]"),
                 ("pooled", "pooled [all senses]"), ("joints only", "pooled [joints]"),
                 ("ee_pixel only", "pooled [ee_pixel]"))
AGENCY = Recipe(
    name="agency",
    about="did I do it? nao_arm, 200 episodes, analytic ee_pixel + joints (README: agency)",
    steps=(_benchmark("agency", "evaluate agency --no-plots"),),
    table=Table(marker="agency", step="agency", csv="roc.csv", key="comparison",
                rows=(Row("0", "0"), Row("100 ms", "100"), Row("200 ms", "200")),
                columns=(*(column(header, "auc", row=f"delay={{}}ms {label}") for header, label in AGENCY_SENSES),
                         column("pooled, delay known", "auc", row="delay={}ms known pooled [all senses]"))),
)


def _success(controller: str) -> tuple[Part, ...]:
    """'95 % (91 % within 1 px)': the ee success, then the goal-space one."""
    return Part("success", controller, 100.0), Part("goal_success", controller, 100.0)


IMAGE_GOAL = "evaluate reaching --model {decoder} --model analytic:nao_arm:joints"
REACHING = Recipe(
    name="reaching",
    about="reaching, 100 targets (20 where the README says), 3 s, seed 0: the rows with analytic models and the "
          "image goals with the levels' decoder and encoder (README: Reaching)",
    steps=(NAO_DATA, DECODER, ENCODER,
           _benchmark("reach_panda", "evaluate reaching --robot panda"),
           _benchmark("reach_panda_off", "evaluate reaching --robot panda --goal-inference off"),
           _benchmark("reach_panda_aic", "evaluate reaching --robot panda --panda-controller aic"),
           _benchmark("reach_image", IMAGE_GOAL + " --encoder {encoder}"),
           _benchmark("reach_image_random", IMAGE_GOAL + " --trials 20"),
           _benchmark("reach_image_off", IMAGE_GOAL + " --trials 20 --goal-inference off"),
           _benchmark("reach_pixel", "evaluate reaching --robot nao_arm"),
           _benchmark("reach_pixel_depth", "evaluate reaching --robot nao_arm --depth-cue-deg 4"),
           _benchmark("reach_planar2", "evaluate reaching --robot planar2"),
           _benchmark("reach_planar2_off", "evaluate reaching --robot planar2 --goal-inference off")),
    table=Table(marker="reaching", step="reach_panda", csv="summary.csv", key="controller",
                rows=(Row("panda, ee_xyz (velocity", step="reach_panda"),
                      Row("panda, ee_xyz, without goal inference", step="reach_panda_off"),
                      Row("panda, ee_xyz, the AIC", step="reach_panda_aic"),
                      Row("nao_arm, image goal: pixel decoder + joints, `--encoder`", step="reach_image"),
                      Row("nao_arm, image goal, goal inference without the encoder", step="reach_image_random"),
                      Row("nao_arm, image goal, without goal inference", step="reach_image_off"),
                      Row("nao_arm, ee_pixel (pixel + joints)", step="reach_pixel"),
                      Row("nao_arm, ee_pixel + depth cue", step="reach_pixel_depth"),
                      Row("planar2, ee_xyz, full ranges", step="reach_planar2"),
                      Row("planar2, ee_xyz, full ranges, without goal inference", step="reach_planar2_off")),
                columns=(Column("AIF success", _success("aif")),
                         Column("AIF median / mean error", (Part("ee_err_median_mm", "aif"), Part("ee_err_mm", "aif"))),
                         column("AIF time", "time_to_reach_s", row="aif"),
                         column("imagined pose's ee error (median)", "imagined_ee_err_mm", row="aif"),
                         Column("PD success", _success("pd")),
                         column("PD mean error", "ee_err_mm", row="pd"),
                         column("PD time", "time_to_reach_s", row="pd"))),
)

IMITATOR_DELAYS = (("imitator d = 0", "0.00"), ("0.05 s", "0.05"), ("0.1 s", "0.10"), ("0.2 s", "0.20"),
                   ("0.5 s", "0.50"))
SELF_RECOGNITION = Recipe(
    name="self-recognition",
    about="is this me? nao_arm, 100 episodes per condition, 20 frames of 0.05 s, seed 0: the exact ee_pixel model, "
          "a GPR of ee_pixel and the levels' pixel decoder on the levels' store, that decoder fused with the GPR, and "
          "the decoder with its former per-frame start (README: Self-recognition)",
    steps=(NAO_DATA, DECODER, GPR_EE_PIXEL,
           _benchmark("self_exact", "evaluate self-recognition --model analytic:nao_arm:ee_pixel --no-plots"),
           _benchmark("self_gpr", "evaluate self-recognition --model {gpr_ee_pixel} --no-plots"),
           _benchmark("self_decoder", "evaluate self-recognition --model {decoder} --no-plots"),
           _benchmark("self_fused", "evaluate self-recognition --model {decoder} --model {gpr_ee_pixel} --no-plots"),
           _benchmark("self_decoder_before", "evaluate self-recognition --model {decoder} --start previous "
                                             "--perception.method flow --no-plots")),
    table=Table(marker="self-recognition", step="self_exact", csv="summary.csv", key="comparison",
                rows=(Row("exact (", step="self_exact"), Row("GPR (ee_pixel", step="self_gpr"),
                      Row("pixel decoder (`dec_hand`", step="self_decoder"),
                      Row("pixel decoder + GPR ee_pixel, fused", step="self_fused"),
                      Row("pixel decoder, before", step="self_decoder_before")),
                columns=(column("AUC pooled", "auc", row="pooled"),
                         *(column(header, "auc", row=f"imitator_{d}s") for header, d in IMITATOR_DELAYS),
                         column("second arm", "auc", row="second_arm"),
                         Column("pooled AUC after 0.25 s", (Part("auc", "pooled,0.25", csv="viewing_time.csv",
                                                                 key="comparison,viewing_s"),)),
                         Column("t95 at d = 0.05 / 0.2 / 0.5 s", tuple(Part("t95_s", f"imitator_{d}s")
                                                                       for d in ("0.05", "0.20", "0.50"))))),
)

RECIPES: dict[str, Recipe] = {r.name: r for r in (LEVELS, RUBBER_HAND, AGENCY, REACHING, SELF_RECOGNITION)}
