"""The tool against the skin: its shapes, poses and probes (tool_geometry.py), the contact kernels of Eq. 3
(kernels.py), and the penalty contact rows an implicit step takes (rows.py)."""
