"""``hierloco verdicts``: see :mod:`recipes.verdicts`."""

import sys

from hierloco.recipes.verdicts import main

sys.exit(main())
