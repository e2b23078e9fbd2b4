"""``python -m ecs_anim.io.library [--check]``: write or check the shipped motion library."""

import sys

from ecs_anim.io.library.shipped import main

sys.exit(main())
