import sys

from cdam_core.cli.main import main

sys.exit(main())
