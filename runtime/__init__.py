"""What the operators and the panel share, so that neither imports the other: the bpy <-> numpy
bridge, the table of Python packages, the running reconstruction and package install, and the
wording of what the user reads."""
