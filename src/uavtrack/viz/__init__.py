"""Pictures of a run: `scene`, one drawing of a step (the environment's render,
``uavtrack animate``, Fig. 4), and `rerun`, the run in Rerun's interactive viewer
(``uavtrack run --rerun``). Each module is loaded on use: matplotlib and Rerun are
imported only by the command that draws.
"""
