build-cg2/core/parallel.o: core/parallel.c core/parallel.h core/error.h
core/parallel.h:
core/error.h:
