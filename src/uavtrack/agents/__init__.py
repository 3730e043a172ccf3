"""The decision cycle as a swarm of programs: one per UAV, exchanging real messages.

    world program: truth, each UAV's measurements, radio range, faults, clock
      | own measurements (Sense)                               ^ action (Report)
      v                                                        |
    UAV program i  <-- beacons, D_i flooding, consensus tuples, bids (Radio) -->  UAV program q
                   <-------------- transport: memory | zenoh -------------->

* `agent`: a UAV's program (`UavAgent`) and the central node (`CentralAgent`), calling
  the simulator's stage functions on their own slice;
* `world`: the world program (`WorldProgram`);
* `messages`: the typed, versioned messages;
* `transport`: the in-process bus and Zenoh (peer mode);
* `swarm`: `run_swarm`, which starts and stops everything;
* `program`: the main loop of one program (``python -m uavtrack.agents``).

With the same seed, scenario and faults, a swarm's trace equals `uavtrack.simulate`'s.
"""

from .swarm import TRANSPORTS, SwarmResult, run_swarm

__all__ = ["TRANSPORTS", "SwarmResult", "run_swarm"]
