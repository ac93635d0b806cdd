"""``python -m socnav_wm.cli``: the ``socnav-wm`` command line."""

from socnav_wm.cli import main

main()
