"""``python -m recipes.verdicts``: see :mod:`recipes.verdicts`."""

import sys

from recipes.verdicts import main

sys.exit(main())
