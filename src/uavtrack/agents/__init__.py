"""The decision cycle as a swarm of programs: one per UAV, exchanging real messages.

    world program: truth, each UAV's measurements, radio range, faults, clock
      | own measurements (Sense)                               ^ action (Report)
      v                                                        |
    UAV program i  <-- D_i flooding with consensus, beacons with bids (Radio) -->  UAV program q
                   <---------- transport: memory | zenoh, one key per program ---------->

* `agent`: a UAV's program (`UavAgent`) and the central node (`CentralAgent`), calling
  the simulator's stage functions on their own slice;
* `world`: the world program (`WorldProgram`);
* `messages`: the typed, versioned messages and what a run admits in them;
* `security`: keys, message authentication and replay windows (`Gate`);
* `transport`: the in-process bus and Zenoh (peer mode, optionally TLS), the `Mailbox`;
* `swarm`: `run_swarm`, which starts and stops everything;
* `program`: the main loop of one program (``python -m uavtrack.agents``);
* `launcher`: the process that forks a swarm's programs from modules loaded once;
* `tracked`: a UAV's program and the central node with tracks of unknown association;
* `schema`: the messages' fields as the documentation lists them (agents-messages);
* `tls`: the checks of TLS files before Zenoh reads them;
* `stops`: how a program notices that its own process was stopped (SIGSTOP).

With the same seed, scenario and faults, a swarm's trace equals `uavtrack.simulate`'s.
"""

import importlib

__all__ = ["TRANSPORTS", "SwarmResult", "run_swarm"]


def __getattr__(name: str):
    # lazily: a program started as ``python -m uavtrack.agents`` reads its spec first
    if name in __all__:
        return getattr(importlib.import_module(".swarm", __name__), name)
    raise AttributeError(f"module 'uavtrack.agents' has no attribute {name!r}")
