"""Pipelines that take a flight log through the link layer and the model core to a result.

A pipeline is library code that more than one caller needs (a command, the demos, the benchmarks), so it lives
below all of them: it may import ``monitor.errors``, ``monitor.files``, ``monitor.wire``, ``monitor.link`` and
``monitor.model``; never ``monitor.service``, ``monitor.demo`` or ``monitor.commands``. A command parses its
arguments, calls a pipeline and prints.
"""
