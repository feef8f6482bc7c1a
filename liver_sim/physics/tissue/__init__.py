"""The tissue laws and what holds the organ: Eq. 1 springs (springs.py; the law and its kernels, spring_law.py),
materials → spring constants, co-rotational tetrahedra (fem_kernels.py), the organ's ligaments (organ_support.py)."""
