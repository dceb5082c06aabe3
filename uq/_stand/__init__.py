"""Layer 4: the virtual test stand, which follows the paper's procedure and error budget."""

# The springs not smooth in pressure register themselves in uq._stand.simulator.SPRINGS; importing
# them here makes them known whichever module of the stand is imported first.
from uq._stand import not_smooth as _not_smooth  # noqa: F401
