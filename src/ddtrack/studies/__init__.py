"""Studies of many runs: a study's cells batched by the program they share (:mod:`ddtrack.studies.cells`)."""
