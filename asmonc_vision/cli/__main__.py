import sys

from asmonc_vision.cli.main import main

sys.exit(main())
