"""Sweeps over scenes, settings and scene parameters, on Dask distributed: ``vjm sweep``,
``vjm tune``, and the engine ``vjm bench --workers`` runs on."""
