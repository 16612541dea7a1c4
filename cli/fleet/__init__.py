"""``nlsid batch``: one single-recording pipeline mapped over many recordings.

- :mod:`nlsid.batch.inputs` finds the recordings (globs, folders, list files) and names them;
- :mod:`nlsid.batch.pipeline` checks a pipeline with the ``{recording}``/``{out}``/``{name}``
  placeholders and decides which recordings are up to date;
- :mod:`nlsid.batch.task` runs the pipeline on one recording (the steps of ``nlsid run``, in the
  worker process) into a work folder that is renamed onto the recording's folder when done;
- :mod:`nlsid.batch.pool` (local processes) and :mod:`nlsid.batch.cluster` (Dask distributed) run
  the tasks;
- :mod:`nlsid.batch.results` writes ``results.csv``/``results.jsonl`` and finds drifts;
  :mod:`nlsid.batch.fleet_page` the fleet page.
"""
