"""A run folder: what ``config.json`` records (:mod:`~gsseg.run.record`), every file of the
folder (:mod:`~gsseg.run.folder`) and the loaded run that renders its views
(:mod:`~gsseg.run.loaded`)."""
