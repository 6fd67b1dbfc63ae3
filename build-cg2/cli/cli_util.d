build-cg2/cli/cli_util.o: cli/cli_util.c cli/cli.h
cli/cli.h:
