"""phiscene: physically grounded image-to-3D scene reconstruction (phi-Scene).

The package holds every computation of the workflow; Snakemake rules and the
``phiscene`` command only orchestrate. See docs/DESIGN.md for the architecture.
"""

from phiscene.errors import InputError, PhisceneError

__all__ = ["PhisceneError", "InputError", "__version__"]
__version__ = "0.1.0"
