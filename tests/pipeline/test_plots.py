"""The shared bar chart: the legend sits between the title and the axes, never over the bars."""

from lerobot_blindgrasp.results import plots


def test_bar_chart_legend_is_above_the_axes_and_below_the_title(tmp_path, monkeypatch):
    figs, close = [], plots.plt.close
    monkeypatch.setattr(plots.plt, "close", figs.append)  # keep the figure to measure it
    labels = [
        "Student (Proposed)",
        "Student w/o Stochastic Teacher",
        "Student w/o Curation",
        "Student w/o r_i",
        "RL w/ o_t",
    ]
    for n_objects in (18, 3):  # the widest chart (Table V) and the narrowest one
        names = [f"object_{k}" for k in range(n_objects)]
        plots.bar_chart(tmp_path / "c.png", names, {label: [100.0] * n_objects for label in labels}, "t", "y")
        fig = figs.pop()
        r = fig.canvas.get_renderer()
        ax, legend = fig.axes[0], fig.axes[0].get_legend()
        title = next(t for t in [*fig.texts, ax.title] if t.get_text() == "t")
        box, axes_box, title_box = (a.get_window_extent(r) for a in (legend, ax, title))
        assert box.y0 >= axes_box.y1  # bars reach the top of the axes (100 %): nothing of the legend is there
        assert box.y1 <= title_box.y0 and title_box.y1 <= fig.bbox.y1
        assert fig.bbox.x0 <= box.x0 and box.x1 <= fig.bbox.x1  # the whole legend is in the picture
        close(fig)
    assert (tmp_path / "c.png").stat().st_size > 1000
