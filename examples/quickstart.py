"""Run the paper's method and both baselines on one trial and plot the paths.

python examples/quickstart.py
"""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

import uavtrack

scenario = uavtrack.Scenario(steps=300)  # the paper's default scenario, shortened
results = {
    m: uavtrack.simulate(scenario, m, seed=1) for m in ("distributed", "centralized", "greedy")
}
for name, r in results.items():
    print(
        f"{name:12s} observation rate {r.observation_rate:.3f}  per target {r.per_target.round(3)}"
    )

trace = results["distributed"].trace
fig, ax = plt.subplots(figsize=(7, 6))
for j in range(scenario.n_targets):
    label = "targets (truth)" if j == 0 else None
    ax.plot(trace.targets[:, j, 0], trace.targets[:, j, 1], "k-", lw=2, label=label)
for i in range(scenario.n_uavs):
    ax.plot(trace.uavs[:, i, 0], trace.uavs[:, i, 1], lw=0.6, label=f"UAV {i}")
field = scenario.field_size
ax.add_patch(plt.Rectangle((0, 0), field, field, fill=False, ls=":", color="gray"))
ax.set_aspect("equal")
ax.set_xlabel("x [m]")
ax.set_ylabel("y [m]")
ax.set_title(
    f"distributed, seed 1, {scenario.steps} steps: observation rate "
    f"{results['distributed'].observation_rate:.3f}"
)
ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
fig.tight_layout()
fig.savefig("quickstart.png", dpi=100)
print("wrote quickstart.png")
