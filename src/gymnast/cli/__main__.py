"""`python -m gymnast.cli ...` (as torchrun starts it) runs the `gymnast` command."""

from gymnast.cli.app import main

main()
