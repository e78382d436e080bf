"""save_figure writes the format a plot path's suffix names, and PNG for any other suffix or none (matplotlib
raised on `--plot views.json` or `--plot views`, after the whole run)."""

from __future__ import annotations

import pytest

from kinfu_cli.report.figures import save_figure


@pytest.mark.parametrize("name, magic", [("plot", b"\x89PNG"), ("plot.json", b"\x89PNG"), ("plot.PNG", b"\x89PNG"),
                                         ("plot.pdf", b"%PDF"), ("plot.SVG", b"<?xml")])
def test_any_plot_path_gets_an_image(tmp_path, name, magic):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(1, 1))
    ax.plot([0, 1], [1, 0])
    out = save_figure(fig, tmp_path / name, dpi=20)
    assert out == tmp_path / name
    assert out.read_bytes().startswith(magic)
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith(".kinfu")) == [name]
