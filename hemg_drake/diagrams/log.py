"""Logging several output ports into one ``VectorLogSink``, and reading the log back by name."""

from pydrake.systems.primitives import LogVectorOutput, Multiplexer


def add_logger(builder, sources, period, *, name="logger"):
    """Log the ``sources`` (name -> output port), stacked in their order, every ``period`` s.

    Returns the ``VectorLogSink`` (named ``name``; its mux ``name + "_mux"``).
    """
    ports = list(sources.values())
    mux = builder.AddNamedSystem(f"{name}_mux", Multiplexer([port.size() for port in ports]))
    for i, port in enumerate(ports):
        builder.Connect(port, mux.get_input_port(i))
    logger = LogVectorOutput(mux.get_output_port(), builder, period)
    logger.set_name(name)
    return logger


def split_log(log, widths):
    """The columns of a ``VectorLog`` written by :func:`add_logger`, split by source.

    ``widths`` maps each source's name to its size, in the logger's order; returns name ->
    array of shape (T, size).
    """
    data, fields, row = log.data(), {}, 0
    for name, width in widths.items():
        fields[name] = data[row : row + width].T
        row += width
    return fields
