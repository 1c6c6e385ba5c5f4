/* The digest of the DAQP sources this library was built from (equilibrist.native.daqp_library),
 * read from the file's bytes. */
const char eq_daqp_digest[] = "equilibrist DAQP sources " EQ_DAQP_DIGEST;
