"""The airspace the team shares, beyond the paper, whose Sec. 8 leaves horizontal
collision avoidance out:

* `separation`: the separation between UAVs that fly in one altitude band, measured in
  every run;
* `avoidance`: the filter on each UAV's action that keeps that separation from the
  neighbours it heard (``planner.avoidance``);
* `beacons`: a receiver's check of those neighbours' beacons against what it already
  knows (the sender's earlier beacon, the radio's range, the start);
* `response`: how an aircraft answers each action, measured by flying its flight model,
  for the filter's measured model (``planner.avoidance_model``)."""
