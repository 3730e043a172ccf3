"""Tracks with unknown association: what a UAV knows when its measurements arrive
unlabelled, missed or false (``tracker.association`` = gnn or jpda).

Each UAV holds up to K track slots (``tracker.max_tracks``), each with a team label, a
status (tentative or confirmed) and its filter; the modules here associate measurements
with tracks (gating, GNN, JPDA), start, confirm and delete tracks, associate the tracks of
neighbours with one's own before fusing them, and score tracks against the truth.
"""
