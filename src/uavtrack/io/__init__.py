"""Outside formats: the trace file (`trace`), tidy tables and xarray (`tables`, the io
extra), Stone Soup's types (`stonesoup`).

    from uavtrack.io import trace, tables
    saved = trace.read("run.npz")                       # uavtrack run --trace run.npz
    ds = tables.to_xarray(saved.trace, saved.scenario, saved.method, saved.seed)
    frames = tables.to_frames(saved.trace, saved.dt)     # steps, uavs, targets, pairs
"""
