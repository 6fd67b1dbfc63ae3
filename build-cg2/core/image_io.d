build-cg2/core/image_io.o: core/image_io.cpp core/image_io.h core/image.h \
 core/vec.h core/error.h
core/image_io.h:
core/image.h:
core/vec.h:
core/error.h:
