"""``nlsid batch``: one single-recording pipeline mapped over many recordings.

Part of the command line: a batch runs pipelines of command lines (the steps of ``nlsid run``)
in worker processes, so it sits beside the commands, on top of the library.

- :mod:`nlsid.cli.fleet.inputs` finds the recordings (globs, folders, list files) and names them;
- :mod:`nlsid.cli.fleet.pipeline` checks a pipeline with the ``{recording}``/``{out}``/``{name}``
  placeholders and decides which recordings are up to date;
- :mod:`nlsid.cli.fleet.task` runs the pipeline on one recording (the steps of ``nlsid run``, in the
  worker process) into a work folder that is renamed onto the recording's folder when done;
- :mod:`nlsid.cli.fleet.pool` (local processes) and :mod:`nlsid.cli.fleet.cluster` (Dask distributed) run
  the tasks;
- :mod:`nlsid.cli.fleet.results` writes ``results.csv``/``results.jsonl`` and finds drifts;
  :mod:`nlsid.cli.fleet.fleet_page` the fleet page.
"""
