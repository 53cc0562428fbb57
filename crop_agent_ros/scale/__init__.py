"""Scale-out on Ray: ``crop-sim sweep`` (training and evaluation sweeps scheduled by Ray Tune) and the
distributed evaluation of ``crop-sim evaluate --address``. Ray loads only when these commands run."""
