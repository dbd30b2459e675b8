"""Inputs: ordinary images (``images``), raw camera files (``rawio``), rig files (``rigfile``), and what
``tpnet process`` makes of its arguments - frames, rig and the pipeline for them (``stereo_io``)."""
