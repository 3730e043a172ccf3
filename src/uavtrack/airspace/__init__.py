"""The airspace the team shares: separation between UAVs that fly in one altitude band
(`separation`), measured in every run; beyond the paper, whose Sec. 8 leaves horizontal
collision avoidance out."""
