from splatting.cli import main

raise SystemExit(main())
