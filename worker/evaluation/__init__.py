"""The paper's evaluation protocol (sec. 4) on a labelled mesh collection.

One module per concern:

* :mod:`.datasets`: ``labels.csv`` (:func:`~.datasets.read_labels`) and where the
  shared data sets live (:func:`~.datasets.shared_dataset`);
* :mod:`.cache`: descriptors on disk, keyed by file bytes, preset and engine source;
* :mod:`.compute`: every mesh described in worker processes, with the ShapeDNA
  baseline (:mod:`.shapedna`) on the same resampled mesh;
* :mod:`.scoring` and :mod:`.metrics`: pure functions from descriptors to
  dissimilarity matrices to every number of the report;
* :mod:`.report` and :mod:`.plots`: report.json, report.md, the CMC and ROC plots;
* :mod:`.run`: :func:`~.run.run_evaluation` ties them together (``shapes evaluate``).

Protocol (also written into every report, see :func:`.report.protocol_text`):

* verification over all unordered pairs (ROC, EER);
* identification with a gallery of the first instance of each class in natural
  file-name order, every other object a probe (CMC, R1RR);
* leave-one-out all-to-all retrieval (NN, first/second tier, E-measure, DCG, mAP).
"""
