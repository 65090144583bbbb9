import sys

from cdprhost.cli.main import main

sys.exit(main())
