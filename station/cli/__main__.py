"""``python -m station.cli``: the ``harp`` command line (:func:`station.cli.main`)."""

import sys

from station.cli import main

sys.exit(main())
