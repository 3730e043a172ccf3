"""Tracks with unknown association: what a UAV knows when its measurements arrive
unlabelled, missed or false (``tracker.association`` = gnn or jpda).

Each UAV holds up to K track slots (``tracker.max_tracks``), each with a team label, a
status (tentative or confirmed) and its filter; the modules here associate measurements
with tracks (gating, GNN, JPDA), start, confirm and delete tracks, associate the tracks of
neighbours with one's own before fusing them, and score tracks against the truth:

* `scan`: each UAV's scan, detections and clutter, as the sensor gives them;
* `association`: gating, GNN and JPDA of a scan with the tracks;
* `manage`: a UAV's slots and their life (update, confirmation, deletion, births);
* `team`: the team's agreement on tracks (track-to-track association, labels);
* `columns`: bids and the auction over team labels;
* `scoring`: the tracks against the truth (GOSPA, switches, SIAP, NEES).
"""
