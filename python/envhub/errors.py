"""`envhub.errors`: the exception classes, one per error kind (defined in `envhub.wire.errors`,
which both sides of a session share; this name stays for users and the compiled module)."""

from .wire.errors import *  # noqa: F403
from .wire.errors import __all__  # noqa: F401
