build-cg2/core/image.o: core/image.c core/image.h core/vec.h core/error.h
core/image.h:
core/vec.h:
core/error.h:
