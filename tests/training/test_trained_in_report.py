"""Issue 35 item 7: `train` writes a models section. Each training run leaves summary.md in its run folder (its model
card, the version it registered, its plots), and `bodyschema report` shows each model trained under --run-root as
a "trained" section, after the data and before the benchmarks, its held-out scores as the key figure."""

import re

from bodyschema.evaluation.report import ReportConfig, write_report
from bodyschema.training.train import train
from tests.evaluation.test_report_models import GPR, levels_run
from tests.training.tiny_model import tiny_config


def test_a_trained_model_is_a_report_section_with_its_card_scores_and_plots(workdir, kin_store, tiny_kind):
    result = train(tiny_config(kin_store, epochs=3))
    summary = (result.run_dir / "summary.md").read_text()
    assert f"- val_rmse: {result.metrics['val_rmse']:.6g}" in summary
    assert f"Registered: {result.registered_name} v1 (now @champion)" in summary
    assert "![loss_curves](plots/loss_curves.png)" in summary
    assert not list(result.run_dir.glob(".summary.md.*")), "no partial file left"

    levels_run(workdir / "results" / "levels", GPR, 1.5, seed=0)
    page = write_report(ReportConfig(results=workdir / "results", trained=workdir / "runs"))
    text = page["markdown"].read_text()
    heads = re.findall(r"^## (.+)$", text, flags=re.M)
    trained = f"trained · planar2 · {result.run_dir.name.rsplit('-', 1)[0]}"
    assert heads.index(trained) < heads.index("levels · nao_arm"), heads
    figure = rf"val_mean_error \S+ m, val_rmse {result.metrics['val_rmse']:.6g} m"    # its card's scores, in m
    assert re.search(rf"\[{re.escape(trained)}\]\(#[^)]*\): {figure}", text)
    assert "loss_curves" in page["html"].read_text()
    assert "trained ·" not in write_report(ReportConfig(results=workdir / "results", trained=None))["markdown"] \
        .read_text()


def test_a_run_without_summary_is_not_a_section(workdir, kin_store, tiny_kind):
    result = train(tiny_config(kin_store, epochs=2))
    (result.run_dir / "summary.md").unlink()                                   # as a run killed before its end
    levels_run(workdir / "results" / "levels", GPR, 1.5, seed=0)
    text = write_report(ReportConfig(results=workdir / "results", trained=workdir / "runs"))["markdown"].read_text()
    assert "## trained" not in text
