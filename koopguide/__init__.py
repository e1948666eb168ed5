"""koopguide: learn goal-converging flow fields from demonstrations (KoopMotion) and steer boats on them.

Query side (numpy only)::

    import koopguide
    field = koopguide.load_field("zshape.pt")
    field.velocity([-30.0, 40.0])
"""

from koopguide.field import FlowField, load_field
from koopguide.modelfile import ModelFileError

__all__ = ["FlowField", "ModelFileError", "load_field"]
__version__ = "0.1.0"
