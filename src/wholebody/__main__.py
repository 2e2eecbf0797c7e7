"""``python -m wholebody`` is the ``wholebody`` command."""

from wholebody.cli import main

raise SystemExit(main())
