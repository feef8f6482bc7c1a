"""The tools on the liver: one tool (tool.py), its use, press, grasp or cut (use.py), and the stiffness it meets
(local_stiffness.py)."""
