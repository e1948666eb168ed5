"""koopguide: learn goal-converging flow fields from demonstrations (KoopMotion) and steer boats on them.

Query side (numpy only)::

    import koopguide
    field = koopguide.load_field("zshape.pt")
    field.velocity([-30.0, 40.0])
"""

from koopguide.base.modelfile import ModelFileError
from koopguide.model.field import FlowField, load_field

__all__ = ["FlowField", "ModelFileError", "load_field"]
__version__ = "0.1.0"
