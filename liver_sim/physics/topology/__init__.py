"""Changes of the mesh's topology: a change and its carry-over (change.py), tearing and cutting."""
