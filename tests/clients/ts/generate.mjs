// Generate schema.d.ts from openapi.yaml, binary bodies and downloads typed as Blob.
import fs from "node:fs";
import openapiTS, { astToString } from "openapi-typescript";
import ts from "typescript";

const BLOB = ts.factory.createTypeReferenceNode(ts.factory.createIdentifier("Blob"));
const [spec, out] = process.argv.slice(2);
const ast = await openapiTS(new URL(spec, `file://${process.cwd()}/`), {
  // A parameter with a default may be left out of a request (the default would otherwise
  // make it required in request bodies too).
  defaultNonNullable: false,
  transform(schema) {
    if (schema.format === "binary") return BLOB;
  },
});
fs.writeFileSync(out, astToString(ast));
