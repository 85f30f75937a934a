"""The tuning lab (``inclinometer tune``): parameter studies of a filter over recordings with
a reference, cross-validated by trial, on local worker processes or a Dask cluster.

- :mod:`.grid`: the parameter axes and the points of a grid or a random search;
- :mod:`.trials`: one filter run on one recording, scored as ``evaluate`` scores it;
- :mod:`.runner`: where the runs go (this process, worker processes, a Dask cluster);
- :mod:`.cv`: folds by trial (k-fold, leave-one-group-out) and the held-out score;
- :mod:`.study`: a whole study (grid, runs, cross-validation, sensitivity) as a JSON-ready dict;
- :mod:`.report`: its tables as text (the plot: :mod:`app.documents.tuning_plot`).
"""
