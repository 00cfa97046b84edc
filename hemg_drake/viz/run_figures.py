"""The pictures a run folder gets from the pipeline's stages (:mod:`hemg_drake.pipeline`):
the demonstrations' figures, the learnt states', the reproduction's, the placements' and the
diagrams'."""

from pathlib import Path

from hemg_drake.viz import figures
from hemg_drake.viz.diagram_svg import write_diagram_picture


def write_demonstration_figures(demos, scenario, folder):
    """``demonstrations.png`` (Fig. 8 (a)-(b) or Fig. 10) and ``fig6_emg.png`` (Fig. 6 from
    demonstration 1's logged sEMG) in ``folder``.

    Returns
    -------
    list of Path, the two files written.
    """
    folder = Path(folder)
    paths = [folder / "demonstrations.png", folder / "fig6_emg.png"]
    figures.save_figure(figures.plot_demonstrations(demos, task=scenario.task), paths[0])
    envelopes = figures.plot_emg_envelopes(demos[0].emg, per_channel=scenario.emg.per_channel)
    figures.save_figure(envelopes, paths[1])
    return paths


def write_state_activations_figure(time, h, task, folder):
    """``state_activations.png`` (Fig. 8 (c)) in ``folder``: the HSMM's forward variable
    ``h`` (shape (T, N)) over ``time`` (s) of one demonstration of ``task``.

    Returns
    -------
    Path, the file written.
    """
    path = Path(folder) / "state_activations.png"
    figures.save_figure(figures.plot_state_activations(time, h, task=task, along=1), path)
    return path


def write_reproduction_figures(task, demos, log, folder):
    """The reproduction against the demonstrations in ``folder``: ``fig8_reproduction.png``
    for the cotter pin, ``fig10_reproduction.png`` and ``fig11_strokes.png`` (the drawn
    strokes beside the demonstrated ones) for the drawing.

    Returns
    -------
    list of Path, the files written.
    """
    from hemg_drake.evaluation import strokes

    folder = Path(folder)
    if task == "cotter_pin":
        path = folder / "fig8_reproduction.png"
        figures.save_figure(figures.plot_pin_reproduction(demos, log), path)
        return [path]
    drawn = strokes(log.time, log.p_WE, log.f_WE)
    demonstrated = [s for d in demos for s in strokes(d.time, d.p_WE, d.f_WE)]
    paths = [folder / "fig10_reproduction.png", folder / "fig11_strokes.png"]
    figures.save_figure(figures.plot_drawing_reproduction(demos, log), paths[0])
    figures.save_figure(figures.plot_strokes(drawn, demonstrated=demonstrated), paths[1])
    return paths


def write_placements_figure(demos, log, task, X_WT, path):
    """``path`` (PNG): the demonstrations grey and the reproduction red, from above, with
    the scene at ``X_WT`` (:func:`~hemg_drake.viz.figures.plot_placements`)."""
    figures.save_figure(figures.plot_placements(demos, log, task=task, X_WT=X_WT), path)


def write_diagram_pictures(diagrams, folder, *, progress=print):
    """Each diagram of ``diagrams`` (name -> Diagram) as ``folder/name.svg`` (Graphviz,
    every port, two levels deep), or as ``.dot`` text with a one-line hint, given to
    ``progress``, when Graphviz is missing.

    Returns
    -------
    list of Path, the files written.
    """
    written = []
    for name, diagram in diagrams.items():
        path, message = write_diagram_picture(diagram, Path(folder) / name, max_depth=2)
        written.append(path)
        if message:
            progress(message)
    return written


def write_run_diagrams(scenario, placed, folder, *, progress=print):
    """The demonstration and reproduction diagrams of a run (``placed``: its model at the
    scenario's placement) as SVG (Graphviz, every port), or as ``.dot`` text with a one-line
    hint when Graphviz is missing."""
    from hemg_drake.diagrams.demonstration import build_demonstration_diagram
    from hemg_drake.diagrams.reproduction import build_reproduction_diagram

    diagrams = {
        "demonstration_diagram": build_demonstration_diagram(scenario).diagram,
        "reproduction_diagram": build_reproduction_diagram(scenario, placed).diagram,
    }
    return write_diagram_pictures(diagrams, folder, progress=progress)
