"""How well descriptors recognize shapes: the measures the paper validates with, and the
decisions the service takes with them.

Pure numpy, imported by the live service and by the offline evaluation alike, so that
``GET /calibration`` and ``shapes evaluate`` compute the same ROC and EER from the same
pairs:

* :mod:`.metrics`: verification (ROC, EER), identification (CMC, R1RR) and retrieval
  (NN, tiers, E-measure, DCG, mAP) of a dissimilarity matrix (sec. 4);
* :mod:`.calibration`: from genuine and impostor scores to thresholds at a false
  acceptance rate and a calibrated confidence;
* :mod:`.fusion`: one fusion weight per modality, chosen on labelled objects by
  class-stratified cross-validation (``shapes tune``).
"""
